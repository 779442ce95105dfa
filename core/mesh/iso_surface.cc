#include "core/mesh/iso_surface.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/common/unified_allocator.h"
#include "core/math/vec3.h"
#include "core/mesh/mesh_cleanup.h"

namespace plx {
namespace {

// Bricks per slice: 512 k cells, 4.7 MB of counts and offsets, and a cancellation check every
// few tens of milliseconds on a CPU.
constexpr int64_t kBricksPerSlice = 1024;

// Vertices the gradient gives no direction (a flat density around them, rare) take the
// area-weighted normal of their triangles instead.
void FillMissingNormals(TriangleMesh* mesh) {
  std::vector<int64_t> missing;
  for (int64_t v = 0; v < mesh->num_vertices(); ++v) {
    const float* n = &mesh->normals[3 * v];
    if (n[0] == 0.0f && n[1] == 0.0f && n[2] == 0.0f) missing.push_back(v);
  }
  if (missing.empty()) return;
  std::vector<Vec3f> sum(static_cast<size_t>(mesh->num_vertices()), Vec3f{0.0f, 0.0f, 0.0f});
  auto position = [mesh](int32_t v) {
    return Vec3f{mesh->positions[3 * v], mesh->positions[3 * v + 1], mesh->positions[3 * v + 2]};
  };
  for (int64_t t = 0; t < mesh->num_triangles(); ++t) {
    const int32_t* f = &mesh->triangles[3 * t];
    // Twice the area times the unit normal: larger triangles weigh more.
    const Vec3f n = Cross(position(f[1]) - position(f[0]), position(f[2]) - position(f[0]));
    for (int c = 0; c < 3; ++c) sum[f[c]] += n;
  }
  for (int64_t v : missing) {
    const float norm = Norm(sum[v]);
    if (!(norm > 0.0f)) continue;
    const Vec3f n = sum[v] * (1.0f / norm);
    mesh->normals[3 * v] = n.x;
    mesh->normals[3 * v + 1] = n.y;
    mesh->normals[3 * v + 2] = n.z;
  }
}

// The world lattice's cells (cell c spans voxels [c, c + 1] on each axis) whose centres lie in
// `box` on one axis: (c + 0.5) * voxel in [lo, hi), i.e. ceil(lo / voxel - 0.5) <= c <=
// ceil(hi / voxel - 0.5) - 1. Clamped far outside any grid (the box may be any finite size)
// but well inside int64, so the callers' sums cannot overflow.
void RegionCellsOnAxis(double lo, double hi, double voxel, int64_t* first, int64_t* last) {
  constexpr double kFar = 1e15;
  const double a = std::clamp(std::ceil(lo / voxel - 0.5), -kFar, kFar);
  const double b = std::clamp(std::ceil(hi / voxel - 0.5) - 1.0, -kFar, kFar);
  *first = static_cast<int64_t>(a);
  *last = static_cast<int64_t>(b);
}

// Slices of bricks through count -> prefix sum -> emit; each triangle's edge keys are turned
// into vertex indices right away (first appearance order), so only the slice's keys are held.
// With a region, the slices run over the list of the bricks that hold its cells, and the
// kernels mesh only the cells whose centres it holds (MeshOptions::region).
class Extraction {
 public:
  Extraction(const SparseGrid& grid, const GridView& field, float level, Backend& backend,
             const MeshOptions& options)
      : view_(field), backend_(backend), options_(options), table_(1) {
    BuildMarchingCubesTable(table_.data());
    params_.iso_level = level;
    params_.color_mode = options.color_mode;
    params_.table = table_.data();
    if (options.region) ListRegion(grid, *options.region);
  }

  // Bricks the slices run over: the grid's, or the region's list.
  int64_t bricks_to_visit() const {
    return listed_ ? static_cast<int64_t>(slots_.size()) : view_.num_bricks;
  }

  absl::Status Slice(int64_t first_brick, int64_t bricks) {
    const int64_t first_item = first_brick * kBrickVertices;
    const int64_t items = bricks * kBrickVertices;
    counts_.resize(static_cast<size_t>(items));
    offsets_.resize(static_cast<size_t>(items));
    PLX_RETURN_IF_ERROR(backend_.CountIsoTriangles(view_, first_item, items, params_,
                                                   counts_.data(), brick_list()));
    int64_t slice_triangles = 0;
    for (int64_t i = 0; i < items; ++i) {
      offsets_[i] = slice_triangles;
      slice_triangles += counts_[i];
    }
    if (slice_triangles == 0) return absl::OkStatus();
    if (slice_triangles > options_.max_triangles - mesh_.num_triangles()) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "the mesh has more than max_triangles = ", options_.max_triangles,
          " triangles; raise iso_level, use a coarser map or raise the limit"));
    }
    keys_.resize(static_cast<size_t>(3 * slice_triangles));
    PLX_RETURN_IF_ERROR(backend_.EmitIsoTriangles(view_, first_item, items, params_,
                                                  offsets_.data(), keys_.data(), brick_list()));
    mesh_.triangles.reserve(mesh_.triangles.size() + keys_.size());
    for (int64_t key : keys_) {
      const int32_t next = static_cast<int32_t>(unique_keys_.size());
      auto [it, inserted] = vertex_of_key_.try_emplace(key, next);
      if (inserted) {
        if (unique_keys_.size() >= static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
          return absl::ResourceExhaustedError("the mesh has more than 2^31 vertices");
        }
        unique_keys_.push_back(key);
      }
      mesh_.triangles.push_back(it->second);
    }
    return absl::OkStatus();
  }

  absl::StatusOr<TriangleMesh> Finish() {
    // The slices' buffers are no longer needed; give their memory back before the vertices.
    UnifiedVector<uint8_t>().swap(counts_);
    UnifiedVector<int64_t>().swap(offsets_);
    UnifiedVector<int64_t>().swap(keys_);
    UnifiedVector<int32_t>().swap(slots_);
    vertex_of_key_ = {};
    const int64_t n = static_cast<int64_t>(unique_keys_.size());
    UnifiedVector<float> positions(3 * n), normals(3 * n);
    UnifiedVector<uint8_t> colors(3 * n), observed(n);
    PLX_RETURN_IF_ERROR(backend_.ComputeIsoVertices(view_, unique_keys_.data(), n, params_,
                                                    positions.data(), normals.data(),
                                                    colors.data(), observed.data()));
    mesh_.positions.assign(positions.begin(), positions.end());
    mesh_.normals.assign(normals.begin(), normals.end());
    mesh_.colors.assign(colors.begin(), colors.end());
    if (!options_.keep_unobserved) {
      // A triangle goes when none of its corners was seen: one seen corner means it borders
      // what a view saw (the rim of a surface).
      std::vector<uint8_t> keep(static_cast<size_t>(mesh_.num_triangles()));
      for (int64_t t = 0; t < mesh_.num_triangles(); ++t) {
        const int32_t* f = &mesh_.triangles[3 * t];
        keep[t] = observed[f[0]] || observed[f[1]] || observed[f[2]];
      }
      KeepTriangles(&mesh_, keep);
    }
    FillMissingNormals(&mesh_);
    RemoveSmallComponents(&mesh_, options_.min_component_triangles);
    return std::move(mesh_);
  }

 private:
  IsoBrickList brick_list() const {
    return listed_ ? IsoBrickList{slots_.data(), static_cast<int64_t>(slots_.size())}
                   : IsoBrickList{};
  }

  // The region's cell range into params_ (in the index's vertex coordinates) and the slots of
  // the bricks holding any of its cells into slots_. One pass over the bricks' coordinates,
  // a few integer comparisons each: nothing next to meshing them.
  void ListRegion(const SparseGrid& grid, const AxisBox& box) {
    listed_ = true;
    int64_t first[3], last[3];
    for (int a = 0; a < 3; ++a) {
      RegionCellsOnAxis(box.min[a], box.max[a], grid.voxel_size(), &first[a], &last[a]);
      // Index coordinates: the world lattice's less the index's corner.
      const int64_t corner = int64_t{grid.index_min()[a]} * kBrickEdge;
      params_.cell_min[a] = static_cast<int32_t>(
          std::clamp<int64_t>(first[a] - corner, INT32_MIN, INT32_MAX));
      params_.cell_max[a] = static_cast<int32_t>(
          std::clamp<int64_t>(last[a] - corner, INT32_MIN, INT32_MAX));
    }
    const std::vector<int32_t> slots = BricksWithCellsIn(grid, box);
    slots_.assign(slots.begin(), slots.end());
  }

  const GridView view_;
  Backend& backend_;
  const MeshOptions& options_;
  UnifiedVector<MarchingCubesTable> table_;
  IsoSurfaceParams params_;
  bool listed_ = false;            // a region: the slices run over slots_
  UnifiedVector<int32_t> slots_;   // the region's bricks
  UnifiedVector<uint8_t> counts_;
  UnifiedVector<int64_t> offsets_;
  UnifiedVector<int64_t> keys_;
  absl::flat_hash_map<int64_t, int32_t> vertex_of_key_;
  UnifiedVector<int64_t> unique_keys_;
  TriangleMesh mesh_;
};

}  // namespace

std::vector<int32_t> BricksWithCellsIn(const SparseGrid& grid, const AxisBox& box) {
  int64_t first[3], last[3];
  for (int a = 0; a < 3; ++a) {
    RegionCellsOnAxis(box.min[a], box.max[a], grid.voxel_size(), &first[a], &last[a]);
  }
  std::vector<int32_t> slots;
  const std::vector<BrickCoord>& coords = grid.brick_coords();
  for (size_t slot = 0; slot < coords.size(); ++slot) {
    const int64_t c[3] = {coords[slot].x, coords[slot].y, coords[slot].z};
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      // The brick's cells are c * 8 .. c * 8 + 7 of the world lattice.
      inside = c[a] * kBrickEdge + kBrickEdge - 1 >= first[a] && c[a] * kBrickEdge <= last[a];
    }
    if (inside) slots.push_back(static_cast<int32_t>(slot));
  }
  return slots;
}

absl::Status ValidateMeshOptions(const MeshOptions& options) {
  if (!(std::isfinite(options.iso_level) && options.iso_level > 0.0f)) {
    return absl::InvalidArgumentError(
        absl::StrCat("iso_level: must be finite and > 0 (a density in 1/m), got ",
                     options.iso_level));
  }
  if (options.min_component_triangles < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "min_component_triangles: must be >= 0, got ", options.min_component_triangles));
  }
  if (options.max_triangles <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_triangles: must be > 0, got ", options.max_triangles));
  }
  if (options.color_mode != MeshColorMode::kDc &&
      options.color_mode != MeshColorMode::kViewAlongNormal) {
    return absl::InvalidArgumentError("color_mode: unknown");
  }
  if (options.region) return CheckAxisBox(*options.region, "region");
  return absl::OkStatus();
}

absl::StatusOr<TriangleMesh> ExtractMesh(const SparseGrid& grid, Backend& backend,
                                         const MeshOptions& options,
                                         const std::function<bool()>& cancelled) {
  return ExtractFieldMesh(grid, grid.view(), options.iso_level, backend, options, cancelled);
}

absl::StatusOr<TriangleMesh> ExtractFieldMesh(const SparseGrid& grid, const GridView& field,
                                              float level, Backend& backend,
                                              const MeshOptions& options,
                                              const std::function<bool()>& cancelled) {
  PLX_RETURN_IF_ERROR(ValidateMeshOptions(options));
  if (!std::isfinite(level)) {
    return absl::InvalidArgumentError(absl::StrCat("level: must be finite, got ", level));
  }
  return CatchAllocationFailure("extracting the mesh", [&]() -> absl::StatusOr<TriangleMesh> {
    Extraction extraction(grid, field, level, backend, options);
    const int64_t bricks = extraction.bricks_to_visit();
    for (int64_t first = 0; first < bricks; first += kBricksPerSlice) {
      if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
      PLX_RETURN_IF_ERROR(extraction.Slice(first, std::min(kBricksPerSlice, bricks - first)));
    }
    if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
    return extraction.Finish();
  });
}

}  // namespace plx

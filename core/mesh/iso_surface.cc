#include "core/mesh/iso_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

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

// Slices of bricks through count -> prefix sum -> emit; each triangle's edge keys are turned
// into vertex indices right away (first appearance order), so only the slice's keys are held.
class Extraction {
 public:
  Extraction(const SparseGrid& grid, Backend& backend, const MeshOptions& options)
      : view_(grid.view()), backend_(backend), options_(options), table_(1) {
    BuildMarchingCubesTable(table_.data());
    params_.iso_level = options.iso_level;
    params_.color_mode = options.color_mode;
    params_.table = table_.data();
  }

  absl::Status Slice(int64_t first_brick, int64_t bricks) {
    const int64_t first_item = first_brick * kBrickVertices;
    const int64_t items = bricks * kBrickVertices;
    counts_.resize(static_cast<size_t>(items));
    offsets_.resize(static_cast<size_t>(items));
    PLX_RETURN_IF_ERROR(
        backend_.CountIsoTriangles(view_, first_item, items, params_, counts_.data()));
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
                                                  offsets_.data(), keys_.data()));
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
  const GridView view_;
  Backend& backend_;
  const MeshOptions& options_;
  UnifiedVector<MarchingCubesTable> table_;
  IsoSurfaceParams params_;
  UnifiedVector<uint8_t> counts_;
  UnifiedVector<int64_t> offsets_;
  UnifiedVector<int64_t> keys_;
  absl::flat_hash_map<int64_t, int32_t> vertex_of_key_;
  UnifiedVector<int64_t> unique_keys_;
  TriangleMesh mesh_;
};

}  // namespace

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
  return absl::OkStatus();
}

absl::StatusOr<TriangleMesh> ExtractMesh(const SparseGrid& grid, Backend& backend,
                                         const MeshOptions& options,
                                         const std::function<bool()>& cancelled) {
  PLX_RETURN_IF_ERROR(ValidateMeshOptions(options));
  return CatchAllocationFailure("extracting the mesh", [&]() -> absl::StatusOr<TriangleMesh> {
    Extraction extraction(grid, backend, options);
    for (int64_t first = 0; first < grid.num_bricks(); first += kBricksPerSlice) {
      if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
      PLX_RETURN_IF_ERROR(
          extraction.Slice(first, std::min(kBricksPerSlice, grid.num_bricks() - first)));
    }
    if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
    return extraction.Finish();
  });
}

}  // namespace plx

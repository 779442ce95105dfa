#include "core/mesh/observed_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/common/unified_allocator.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/depth_fusion.h"
#include "core/render/render_view.h"

namespace plx {
namespace {

// The keyframe's camera at `scale` of its resolution: pixel coordinates (centres at u + 0.5)
// scale with the image, so the focal lengths and principal point scale by the same factors.
PinholeIntrinsics ScaledIntrinsics(const PinholeIntrinsics& k, double scale) {
  PinholeIntrinsics out = k;
  out.width = std::max(1, static_cast<int>(std::lround(k.width * scale)));
  out.height = std::max(1, static_cast<int>(std::lround(k.height * scale)));
  const double sx = static_cast<double>(out.width) / k.width;
  const double sy = static_cast<double>(out.height) / k.height;
  out.fx = k.fx * sx;
  out.cx = k.cx * sx;
  out.fy = k.fy * sy;
  out.cy = k.cy * sy;
  return out;
}

// False only when no point of `box` can be in the keyframe's view: every corner behind the
// camera or beyond the fused depth, or every corner in front and past one image border (a box
// straddling the camera plane counts as seen). A region's mesh renders only the keyframes that
// may see it, so its cost follows the box.
bool KeyframeMaySee(const MapKeyframe& keyframe, const AxisBox& box, float max_depth) {
  const SE3 camera_T_world = keyframe.pose.Inverse();
  const PinholeIntrinsics& k = keyframe.intrinsics;
  int behind = 0, beyond = 0, left = 0, right = 0, above = 0, below = 0;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d world(c & 1 ? box.max[0] : box.min[0], c & 2 ? box.max[1] : box.min[1],
                                c & 4 ? box.max[2] : box.min[2]);
    const Eigen::Vector3d p = camera_T_world * world;
    if (p.z() <= 0.0) {
      ++behind;
      continue;
    }
    beyond += p.z() > max_depth;
    const double u = k.fx * p.x() / p.z() + k.cx, v = k.fy * p.y() / p.z() + k.cy;
    left += u < 0.0;
    right += u >= k.width;
    above += v < 0.0;
    below += v >= k.height;
  }
  if (behind == 8 || beyond == 8) return false;
  if (behind > 0) return true;
  return left < 8 && right < 8 && above < 8 && below < 8;
}

// options.render_scale, or the smaller scale at which all of `keyframes` render in
// options.max_rendered_pixels (pixels shrink with the square of the scale).
double RenderScaleWithinBudget(const std::vector<const MapKeyframe*>& keyframes,
                               const ObservedSurfaceOptions& options) {
  double pixels = 0.0;
  for (const MapKeyframe* k : keyframes) {
    pixels += static_cast<double>(k->intrinsics.width) * k->intrinsics.height;
  }
  const double scaled = pixels * options.render_scale * options.render_scale;
  if (scaled <= static_cast<double>(options.max_rendered_pixels)) return options.render_scale;
  return options.render_scale * std::sqrt(options.max_rendered_pixels / scaled);
}

// The bricks whose vertices the field needs: every brick, or for a region the bricks of the
// region's cells and of their neighbours two voxels out (a cell's far corners and the
// central-difference normals at them reach that far).
AxisBox FieldBox(const SparseGrid& grid, const AxisBox& region) {
  AxisBox box = region;
  const double margin = 2.0 * grid.voxel_size();
  for (int a = 0; a < 3; ++a) {
    box.min[a] -= margin;
    box.max[a] += margin;
  }
  return box;
}

// Bricks per edge of a group whose vertices share one list of keyframes (ObserveByGroups):
// 4 bricks of 8 voxels, 0.64 m at 2 cm, small against a keyframe's view and large enough that
// a launch has tens of thousands of vertices.
constexpr int kGroupBricks = 4;

int32_t GroupOf(int32_t brick) {
  // Floor division: bricks -1..-4 are group -1.
  return brick >= 0 ? brick / kGroupBricks : -((-brick + kGroupBricks - 1) / kGroupBricks);
}

UnifiedVector<int32_t> FieldBricks(const SparseGrid& grid, const MeshOptions& options) {
  UnifiedVector<int32_t> slots;
  if (!options.region) {
    slots.resize(static_cast<size_t>(grid.num_bricks()));
    for (int64_t s = 0; s < grid.num_bricks(); ++s) slots[s] = static_cast<int32_t>(s);
    return slots;
  }
  const std::vector<int32_t> listed = BricksWithCellsIn(grid, FieldBox(grid, *options.region));
  slots.assign(listed.begin(), listed.end());
  return slots;
}

}  // namespace

absl::Status ObserveFieldByGroups(const SparseGrid& grid, absl::Span<const int32_t> slots,
                                  const std::vector<const MapKeyframe*>& keyframes,
                                  absl::Span<const TrainingFrameView> frames,
                                  const FusionParams& params, float max_depth, Backend& backend,
                                  float* values) {
  if (frames.size() != keyframes.size()) {
    return absl::InvalidArgumentError(absl::StrCat("one view per keyframe: ", frames.size(),
                                                   " views for ", keyframes.size()));
  }
  struct Entry {
    std::array<int32_t, 3> group;
    int32_t slot;
  };
  std::vector<Entry> entries;
  entries.reserve(slots.size());
  for (const int32_t slot : slots) {
    const BrickCoord& b = grid.brick_coords()[slot];
    entries.push_back({{GroupOf(b.x), GroupOf(b.y), GroupOf(b.z)}, slot});
  }
  std::sort(entries.begin(), entries.end(),
            [](const Entry& a, const Entry& b) { return a.group < b.group; });
  // Every group's slots and keyframes, concatenated: two allocations whatever the group count
  // (unified memory is costly to allocate on a GPU).
  UnifiedVector<int32_t> grouped_slots(entries.size());
  struct Group {
    size_t first_slot = 0, slots = 0, first_frame = 0, frames = 0;
  };
  std::vector<Group> groups;
  std::vector<int32_t> frame_index;
  const double voxel = grid.voxel_size();
  const double group_edge = kGroupBricks * kBrickEdge * voxel;
  for (size_t i = 0; i < entries.size();) {
    Group g;
    g.first_slot = i;
    const std::array<int32_t, 3> key = entries[i].group;
    for (; i < entries.size() && entries[i].group == key; ++i) grouped_slots[i] = entries[i].slot;
    g.slots = i - g.first_slot;
    // The group's vertices: brick b's are at (8 b + 0..7) voxels.
    AxisBox box;
    for (int a = 0; a < 3; ++a) {
      box.min[a] = key[a] * group_edge;
      box.max[a] = box.min[a] + group_edge - voxel;
    }
    g.first_frame = frame_index.size();
    for (size_t f = 0; f < keyframes.size(); ++f) {
      if (KeyframeMaySee(*keyframes[f], box, max_depth)) {
        frame_index.push_back(static_cast<int32_t>(f));
      }
    }
    g.frames = frame_index.size() - g.first_frame;
    groups.push_back(g);
  }
  UnifiedVector<TrainingFrameView> grouped_frames(frame_index.size());
  for (size_t i = 0; i < frame_index.size(); ++i) grouped_frames[i] = frames[frame_index[i]];
  for (const Group& g : groups) {
    // No keyframe may see the group: its vertices keep kIsoNoValue, as the kernel would give.
    if (g.frames == 0) continue;
    PLX_RETURN_IF_ERROR(backend.ObserveSurface(
        grid.view(),
        IsoBrickList{grouped_slots.data() + g.first_slot, static_cast<int64_t>(g.slots)},
        grouped_frames.data() + g.first_frame, static_cast<int>(g.frames), params, values));
  }
  return absl::OkStatus();
}

absl::Status ValidateObservedSurfaceOptions(const ObservedSurfaceOptions& options) {
  if (!(options.render_scale > 0.0 && options.render_scale <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("render_scale: must be in (0, 1], got ", options.render_scale));
  }
  if (options.max_rendered_pixels <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("max_rendered_pixels: must be > 0, got ",
                                                   options.max_rendered_pixels));
  }
  if (!(options.truncation_voxels >= 1.0f && std::isfinite(options.truncation_voxels))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "truncation_voxels: must be finite and >= 1, got ", options.truncation_voxels));
  }
  return absl::OkStatus();
}

absl::StatusOr<TriangleMesh> ExtractObservedMesh(const PlenoxelMap& map,
                                                 const MapKeyframes& keyframes, Backend& backend,
                                                 const MeshOptions& options,
                                                 const ObservedSurfaceOptions& surface,
                                                 const std::function<bool()>& cancelled) {
  PLX_RETURN_IF_ERROR(ValidateMeshOptions(options));
  PLX_RETURN_IF_ERROR(ValidateObservedSurfaceOptions(surface));
  if (keyframes.empty()) {
    return absl::FailedPreconditionError(
        "the map has no keyframes, so what they observed is unknown (a map file from before "
        "format version 2, or one saved without them); use the density surface");
  }
  const SparseGrid& grid = map.grid;
  return CatchAllocationFailure("extracting the observed surface",
                                [&]() -> absl::StatusOr<TriangleMesh> {
    // A fixed truncation, not the sensor's noise model: the rendered depth is the optimised
    // map's, and a band grown with range (3 sigma: 12 cm at 5 m) only adds the fringes that
    // a keyframe's view puts behind foreground edges (docs/BENCHMARKS.md, "Surfaces seen
    // once").
    FusionParams params;
    params.min_truncation = surface.truncation_voxels * grid.voxel_size();
    params.truncation_sigmas = 0.0f;
    // A vertex up to a truncation beyond the fused depth still counts (its signed distance to
    // a surface at max_depth is within the band).
    const float see_depth = params.max_depth + params.min_truncation;
    // The keyframes that may see the field's bricks: all of them for the whole map.
    std::vector<const MapKeyframe*> seeing;
    const std::optional<AxisBox> box =
        options.region ? std::optional<AxisBox>(FieldBox(grid, *options.region)) : std::nullopt;
    for (const MapKeyframe& k : keyframes) {
      if (!box || KeyframeMaySee(k, *box, see_depth)) seeing.push_back(&k);
    }
    // Each keyframe's surface depth as the map renders it; only the depth is kept.
    std::vector<DepthImage> depths;
    depths.reserve(seeing.size());
    UnifiedVector<TrainingFrameView> frames(seeing.size());
    RenderViewOptions render_options;
    render_options.cancelled = cancelled;
    const double scale = RenderScaleWithinBudget(seeing, surface);
    for (size_t i = 0; i < seeing.size(); ++i) {
      if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
      const PinholeIntrinsics k = ScaledIntrinsics(seeing[i]->intrinsics, scale);
      PLX_ASSIGN_OR_RETURN(RenderedView view,
                           RenderView(backend, map, seeing[i]->pose, k, render_options));
      depths.push_back(std::move(view.z_depth));
      frames[i].camera = ToKernelCamera(seeing[i]->pose, k);
      frames[i].color = nullptr;
      frames[i].depth = depths.back().data.data();
    }

    UnifiedVector<float> values(static_cast<size_t>(grid.num_vertices()), kIsoNoValue);
    UnifiedVector<const float*> tables(static_cast<size_t>(grid.num_bricks()));
    for (int64_t s = 0; s < grid.num_bricks(); ++s) {
      tables[s] = values.data() + s * kBrickVertices;
    }
    const UnifiedVector<int32_t> slots = FieldBricks(grid, options);
    if (cancelled && cancelled()) return absl::CancelledError("mesh export cancelled");
    PLX_RETURN_IF_ERROR(ObserveFieldByGroups(grid, slots, seeing, frames, params, see_depth,
                                             backend, values.data()));
    depths.clear();

    // The field is -tsdf: positive inside, so the surface is its level 0.
    const GridView field = grid.ViewOf<float>(tables.data(), grid.view().brick_sh);
    return ExtractFieldMesh(grid, field, 0.0f, backend, options, cancelled);
  });
}

}  // namespace plx

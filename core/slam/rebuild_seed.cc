#include "core/slam/rebuild_seed.h"

#include <algorithm>
#include <cmath>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/kernels/refresh_occupancy.h"

namespace plx {

absl::Status ValidateRebuildSeedOptions(const RebuildSeedOptions& o) {
  if (!(o.moved_tolerance_voxels >= 0.0) || !std::isfinite(o.moved_tolerance_voxels)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "rebuild moved tolerance must be a non-negative number of voxels, got ",
        o.moved_tolerance_voxels));
  }
  if (o.pixel_stride < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("rebuild pixel stride must be at least 1, got ", o.pixel_stride));
  }
  return absl::OkStatus();
}

double KeyframeSurfaceShift(const DepthImage& depth, const PinholeIntrinsics& k,
                            const SE3& before, const SE3& after, int pixel_stride,
                            float max_depth) {
  // A world point p seen at `before` is at after * before^-1 * p once the keyframe moves.
  const SE3 move = after * before.Inverse();
  double largest = 0.0;
  const int stride = std::max(1, pixel_stride);
  for (int v = stride / 2; v < depth.height; v += stride) {
    for (int u = stride / 2; u < depth.width; u += stride) {
      const float z = *depth.pixel(u, v);
      if (!(z > 0.0f) || z > max_depth) continue;
      const Eigen::Vector3d camera((u + 0.5 - k.cx) / k.fx * z, (v + 0.5 - k.cy) / k.fy * z, z);
      const Eigen::Vector3d world = before * camera;
      largest = std::max(largest, (move * world - world).norm());
    }
  }
  return largest;
}

absl::StatusOr<KeyframeMoves> MeasureKeyframeMoves(const TrainingSet& keyframes,
                                                   const std::vector<SE3>& before,
                                                   const std::vector<SE3>& after,
                                                   float voxel_size, float max_depth,
                                                   const RebuildSeedOptions& options) {
  PLX_RETURN_IF_ERROR(ValidateRebuildSeedOptions(options));
  const int n = keyframes.num_frames();
  if (static_cast<int>(before.size()) != n || static_cast<int>(after.size()) != n) {
    return absl::InvalidArgumentError(absl::StrCat("measuring moves needs one pose per keyframe (",
                                                   n, "), got ", before.size(), " before and ",
                                                   after.size(), " after"));
  }
  const double tolerance = options.moved_tolerance_voxels * voxel_size;
  KeyframeMoves moves;
  moves.moved.assign(static_cast<size_t>(n), 0);
  for (int i = 0; i < n; ++i) {
    const double shift = KeyframeSurfaceShift(keyframes.frame(i).depth, keyframes.intrinsics(i),
                                              before[i], after[i], options.pixel_stride,
                                              max_depth);
    moves.largest_m = std::max(moves.largest_m, shift);
    if (shift <= tolerance) continue;
    moves.moved[i] = 1;
    ++moves.moved_keyframes;
  }
  return moves;
}

absl::StatusOr<RebuildSeed> SeedRebuild(const PlenoxelMap& map, const TrainingSet& keyframes,
                                        const std::vector<SE3>& before,
                                        const KeyframeMoves& moves,
                                        const AllocationOptions& allocation, Backend& backend) {
  const int n = keyframes.num_frames();
  if (static_cast<int>(before.size()) != n || static_cast<int>(moves.moved.size()) != n) {
    return absl::InvalidArgumentError(absl::StrCat("a rebuild seed needs one pose and one move ",
                                                   "per keyframe (", n, "), got ", before.size(),
                                                   " and ", moves.moved.size()));
  }
  const float voxel = map.grid.voxel_size();
  RebuildSeed seed;
  seed.moved = moves.moved;
  seed.moved_keyframes = moves.moved_keyframes;
  absl::flat_hash_set<BrickCoord> dropped;
  for (int i = 0; i < n; ++i) {
    if (moves.moved[i] == 0) continue;
    for (const BrickCoord& b : BricksNearSurface(keyframes.frame(i).depth, before[i],
                                                 keyframes.intrinsics(i), voxel, allocation)) {
      dropped.insert(b);
    }
  }
  const std::vector<BrickCoord>& coords = map.grid.brick_coords();
  std::vector<uint8_t> keep(coords.size(), 1);
  for (size_t slot = 0; slot < coords.size(); ++slot) {
    if (dropped.contains(coords[slot])) {
      keep[slot] = 0;
      ++seed.dropped_bricks;
    }
  }
  seed.kept_bricks = static_cast<int64_t>(coords.size()) - seed.dropped_bricks;
  auto seeded = std::make_shared<PlenoxelMap>(map.grid.ShareSubset(keep), map.render, map.source);
  // Readers of the rebuild's first version (it is the session's base) march its occupancy.
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(backend, *seeded));
  seed.map = std::move(seeded);
  return seed;
}

}  // namespace plx

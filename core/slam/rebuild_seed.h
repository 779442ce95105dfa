// What a loop correction's rebuild keeps of the map it replaces (docs/SLAM.md, "Loop closure").
// A pose-graph solve moves some keyframes and leaves others where they were (those before the
// loop's start, a second lap that only confirmed the first). The map already fits the keyframes
// that did not move; only what the moved ones saw has to be built again. So the rebuild starts
// from the old map without the bricks the moved keyframes saw at their old poses, fuses those
// keyframes again at their new poses, and earns iterations for them only: its cost follows the
// correction's size, not the map's.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/image.h"
#include "core/geometry/se3.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/brick_allocation.h"
#include "core/mapping/training_set.h"

namespace plx {

struct RebuildSeedOptions {
  // A keyframe moved when one of its depth points moves more than this many voxels: below
  // half a voxel the map's trilinear field is about where it would be, and the iterations the
  // moved neighbours earn fit it the rest of the way.
  double moved_tolerance_voxels = 0.5;
  int pixel_stride = 8;  // every n-th pixel per row and column is checked
};

absl::Status ValidateRebuildSeedOptions(const RebuildSeedOptions& options);

struct RebuildSeed {
  // The old map without the bricks the moved keyframes saw (their allocation band at the old
  // poses), sharing the kept bricks; occupancy fresh.
  std::shared_ptr<const PlenoxelMap> map;
  std::vector<uint8_t> moved;  // per keyframe: 1 = it moved and is fused and budgeted again
  int moved_keyframes = 0;
  int64_t kept_bricks = 0;
  int64_t dropped_bricks = 0;
};

// The largest distance any valid depth point of `depth` (every `pixel_stride`-th pixel, up to
// `max_depth`) moves between world_T_camera `before` and `after`.
double KeyframeSurfaceShift(const DepthImage& depth, const PinholeIntrinsics& intrinsics,
                            const SE3& before, const SE3& after, int pixel_stride,
                            float max_depth);

// Which keyframes a correction from `before` to `after` (one pose each) moves: those whose
// surface shift (above, up to `max_depth`) exceeds options.moved_tolerance_voxels voxels of
// `voxel_size`. Measured once per correction: it decides both whether the correction is
// applied in place and what a seeded rebuild drops. InvalidArgument when the pose lists do not
// match the keyframes or the options are invalid.
struct KeyframeMoves {
  std::vector<uint8_t> moved;  // per keyframe: 1 = it moved
  int moved_keyframes = 0;
  double largest_m = 0.0;      // the largest surface shift of any keyframe
};
absl::StatusOr<KeyframeMoves> MeasureKeyframeMoves(const TrainingSet& keyframes,
                                                   const std::vector<SE3>& before,
                                                   const std::vector<SE3>& after,
                                                   float voxel_size, float max_depth,
                                                   const RebuildSeedOptions& options);

// The seed of a rebuild of `map` (the latest version built from `keyframes` at `before`) once
// the keyframes `moves` names have moved. `allocation` is the mapper's (the bands its
// keyframes allocated). InvalidArgument when `before` or `moves` do not match the keyframes.
absl::StatusOr<RebuildSeed> SeedRebuild(const PlenoxelMap& map, const TrainingSet& keyframes,
                                        const std::vector<SE3>& before,
                                        const KeyframeMoves& moves,
                                        const AllocationOptions& allocation, Backend& backend);

}  // namespace plx

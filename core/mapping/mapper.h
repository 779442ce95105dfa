// RGB-D mapping with known poses (DESIGN.md §7): keyframes in, an optimised PlenoxelMap out.
//   1. bricks are allocated around the surfaces each keyframe's depth measures;
//   2. their vertices are initialised from the depth and colour (core/kernels/depth_fusion.h);
//   3. batches of random rays with valid depth refine density and SH with RMSProp on the
//      colour + depth loss, with log-linear learning-rate decay and optional early TV,
//      until the iteration or time budget is spent.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/kernels/depth_fusion.h"
#include "core/mapping/brick_allocation.h"
#include "core/mapping/training_set.h"

namespace plx {

struct MapperOptions {
  float voxel_size = 0.02f;  // metres
  AllocationOptions allocation;
  FusionParams fusion;
  bool initialize_from_depth = true;  // false: uniform density like the reference (comparison)
  float initial_density = 0.1f;       // used when initialize_from_depth is false

  // Budget: stop at whichever comes first (0 disables that limit; at least one must be set).
  int max_iterations = 2000;
  double time_budget_s = 0.0;

  int batch_size = 8192;
  // Depth term of the loss, see MappingBatchParams (noise model shared with allocation/fusion).
  float depth_weight = 1.0f;
  float depth_huber = 3.0f;
  float sh_min_weight = 1e-4f;
  float lr_density_start = 10.0f, lr_density_end = 1.0f;
  float lr_sh_start = 1e-2f, lr_sh_end = 1e-3f;
  float rmsprop_beta = 0.95f;
  // Total variation on a random 1% run of vertices per iteration during the first
  // tv_until fraction of the budget (Plenoxels applies it only before upsampling).
  float tv_density = 0.0f, tv_sh = 0.0f;
  float tv_fraction = 0.01f, tv_until = 0.5f;

  // Coarse-to-fine: optimise at twice the voxel size until `upsample_at` of the budget, then
  // resample onto the final voxel size and continue (Plenoxels' 256^3 -> 512^3 schedule).
  bool coarse_to_fine = false;
  float upsample_at = 0.5f;

  // Copy-on-write clones per iteration (0 = no limit). After a version is published, the
  // bricks an iteration changes must be cloned first; above this many, the rest wait: their
  // gradients keep accumulating and they are updated by a later iteration once cloned, so no
  // single step pays for cloning most of the map (a mapping session sets this).
  int max_clones_per_iteration = 0;

  // Local window (SLAM): with window_keyframes > 0, window_fraction of each batch is drawn from
  // the rays of the last window_keyframes keyframes and the rest from every keyframe, so new
  // geometry keeps converging while older keyframes still anchor what they saw.
  int window_keyframes = 0;
  float window_fraction = 0.5f;

  uint32_t seed = 20200823;
  RenderOptions render;
  int progress_every = 25;  // iterations between progress reports
};

// Defaults for a voxel size: the lengths that are naturally "a few voxels" scale with it.
MapperOptions MapperOptionsForVoxelSize(float voxel_size);

struct MappingProgress {
  int iteration = 0;
  double elapsed_s = 0.0;
  double progress = 0.0;      // fraction of the budget used
  double psnr = 0.0;          // on the last batch's training rays, colour clamped to [0,1]
  double depth_l1_m = 0.0;    // mean |D^ - D| on the last batch (range, metres)
  double opacity = 0.0;       // mean opacity of the last batch
};

struct MappingSummary {
  int keyframes = 0;
  int64_t training_rays = 0;
  int iterations = 0;
  double allocation_s = 0.0;
  double optimization_s = 0.0;
  MappingProgress last;
  GridMemory memory;
  int64_t optimizer_bytes = 0;  // gradients + RMSProp state
  bool upsampled = false;       // coarse-to-fine switched to the final voxel size
  int64_t cloned_bricks = 0;    // bricks copied because a published version shared them
};

// Return false to stop the optimisation early (cancellation).
using MappingProgressCallback = std::function<bool(const MappingProgress&)>;

class Mapper {
 public:
  // `backend` must outlive the mapper.
  Mapper(const MapperOptions& options, Backend* backend);
  // Continues an existing map (its voxel size wins; no coarse-to-fine).
  Mapper(const MapperOptions& options, Backend* backend, std::unique_ptr<PlenoxelMap> map);

  // Checks options; called by the constructor's users before anything else.
  static absl::Status ValidateOptions(const MapperOptions& options);

  absl::Status AddKeyframe(RgbdFrame frame, const SE3& world_T_camera,
                           const PinholeIntrinsics& intrinsics);

  // Allocates and initialises bricks for the keyframes added since the last call.
  absl::Status AllocateAndInitialize();

  // Runs the optimisation until the budget is spent (or the callback says stop), or for at most
  // `max_new_iterations` iterations / `max_seconds` seconds when those are positive (at least
  // one iteration runs). The budget is cumulative over calls.
  absl::StatusOr<MappingSummary> Optimize(const MappingProgressCallback& progress = nullptr,
                                          int max_new_iterations = 0, double max_seconds = 0.0);

  // Raises or lowers the total iteration budget (e.g. as keyframes stream in). The learning
  // rate follows the largest fraction of the budget reached so far, so raising the budget
  // pauses its decay instead of restarting it.
  void set_max_iterations(int iterations) { options_.max_iterations = iterations; }
  // Where the learning-rate schedule stands, in [0, 1].
  double schedule_fraction() const { return schedule_; }
  int iterations_done() const { return iteration_; }
  bool budget_spent() const {
    return options_.max_iterations > 0 && iteration_ >= options_.max_iterations;
  }

  // A version of the current map for readers (the daemon's published versions), with exact
  // cell occupancy. Copy-on-write: it shares every brick with the mapper's map, which clones a
  // brick before its next change, so this costs the index, not the bricks.
  absl::StatusOr<std::shared_ptr<const PlenoxelMap>> Publish();

  // Moves keyframe i to a refined pose (SLAM's keyframe pose refinement). Its bricks stay
  // where its first pose put them: refinements are small against the allocation band.
  absl::Status SetKeyframePose(int i, const SE3& world_T_camera) {
    return training_.SetPose(i, world_T_camera);
  }

  PlenoxelMap& map() { return *map_; }
  const PlenoxelMap& map() const { return *map_; }
  std::unique_ptr<PlenoxelMap> ReleaseMap() { return std::move(map_); }
  const TrainingSet& training_set() const { return training_; }
  const MappingSummary& summary() const { return summary_; }

 private:
  // Builds the final-resolution map from the keyframes' depth, fills it from the current
  // (coarse) map and restarts the optimiser state.
  absl::Status Upsample();
  absl::Status AllocateFrames(int first_frame, PlenoxelMap& map, float voxel_size);
  void ResizeOptimizerBuffers();
  GridGradView grad_view();
  OptimizerStateView state_view();

  MapperOptions options_;
  Backend* backend_;
  std::unique_ptr<PlenoxelMap> map_;
  TrainingSet training_;
  int allocated_frames_ = 0;  // keyframes whose bricks exist
  bool coarse_ = false;       // the map is at twice the final voxel size
  int iteration_ = 0;
  double schedule_ = 0.0;     // learning-rate schedule position: never decreases
  MappingSummary summary_;

  // Read and written by the backend's kernels: UnifiedVector (core/common/unified_allocator.h).
  UnifiedVector<float> grad_density_, grad_sh_;
  UnifiedVector<uint8_t> touched_, brick_touched_;
  UnifiedVector<float> rms_density_, rms_sh_;
  UnifiedVector<MappingRayLoss> losses_;
  std::vector<int64_t> deferred_;  // touched bricks still shared with a published version
};

}  // namespace plx

// RGB-D mapping with known poses (DESIGN.md §7): keyframes in, an optimised PlenoxelMap out.
//   1. bricks are allocated around the surfaces each keyframe's depth measures;
//   2. their vertices are initialised from the depth and colour (core/kernels/depth_fusion.h);
//   3. batches of random rays with valid depth refine density and SH with RMSProp on the
//      colour + depth loss, with log-linear learning-rate decay and optional early TV,
//      until the iteration or time budget is spent.
//
// Integration in slices (steps 1 and 2, plus what the optimiser needs for the new bricks): one
// keyframe takes seconds on a 640x480 sensor (docs/BENCHMARKS.md, "Mapping steps"), and a
// tracking frame on the same device would wait for all of it. IntegrateSlice does it in pieces,
// each bounded by a count of bricks, vertices, blocks or bytes and sized from the rate the
// previous pieces ran at, until a time budget is spent:
//   list      per keyframe, the bricks near its surfaces and the map-size check (one piece);
//   allocate  those bricks in runs, in the list's order, after the index grew to cover all of
//             them (SparseGrid::PrepareToAllocate): the index and slots one call would give;
//   fuse      FuseDepth over the new vertices in ranges: each vertex is computed from the
//             keyframes alone and written only by itself, so ranges give the values of one call;
//   occupancy exact cell occupancy in runs of active blocks (each block from its own densities);
//   buffers   the optimiser's gradient and RMSProp buffers grown for the new vertices: old
//             contents copied into larger storage in runs instead of one reallocation, then the
//             new entries zeroed in runs (on teddy this was the longest part: up to 6.9 s).
// The result is bit-identical to integrating in one go, whatever the slices. While an
// integration is in progress the map holds allocated but unfused bricks, so it must be neither
// optimised nor published: Optimize and Publish finish the integration first, which makes a
// half-integrated map impossible to optimise or hand out, whoever calls them.
#pragma once

#include <chrono>
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

// The voxel sizes a map may have, in metres: the engine, the daemon's CreateMap and the CLI's
// --voxel-size all check this one range.
inline constexpr double kMinVoxelSize = 0.001;
inline constexpr double kMaxVoxelSize = 1.0;
// False for NaN too.
inline bool VoxelSizeInRange(double voxel_size) {
  return voxel_size >= kMinVoxelSize && voxel_size <= kMaxVoxelSize;
}

// The most rays one mapping iteration may sample (MapperOptions::batch_size; the daemon's
// rays_per_iteration).
inline constexpr int kMaxBatchSize = 1 << 24;

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
  // The most bytes the map may take (SparseGrid::Memory); 0 = no limit. Checked before each
  // keyframe's bricks are allocated (SparseGrid::MemoryAfterAllocating): a keyframe that would
  // take the map over it is refused with RESOURCE_EXHAUSTED and nothing is allocated. The
  // optimiser's state (about twice the map's parameters) comes on top.
  int64_t max_map_bytes = 0;

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

  ~Mapper();

  absl::Status AddKeyframe(RgbdFrame frame, const SE3& world_T_camera,
                           const PinholeIntrinsics& intrinsics);

  // Allocates and initialises bricks for the keyframes added and not integrated yet: every
  // piece of their integration at once (batch mapping).
  absl::Status AllocateAndInitialize();

  // One slice of integration (see the top of this file): starts integrating the keyframes
  // added so far when none is in progress, then runs its pieces until it is done or
  // `max_seconds` have passed (at least one piece; 0 = no limit). True when no integration is
  // in progress afterwards (keyframes added after it began wait for the next one). On an error
  // the integration stays where it was, and the next slice retries the failed piece.
  absl::StatusOr<bool> IntegrateSlice(double max_seconds);
  // An integration has begun and not finished: the map has bricks that are not fused yet.
  bool integrating() const { return integration_ != nullptr; }
  // Keyframes whose integration is complete.
  int integrated_keyframes() const { return integrated_frames_; }

  // Integrates the keyframes that are not yet (AllocateAndInitialize), then runs the
  // optimisation until the budget is spent (or the callback says stop), or for at most
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
  // brick before its next change, so this costs the index, not the bricks. An integration in
  // progress is finished first (all its remaining pieces): a version never has unfused bricks.
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
  struct Integration;  // mapper.cc
  // Every keyframe from first_frame on, in one go (coarse-to-fine's final map).
  absl::Status AllocateFrames(int first_frame, PlenoxelMap& map);
  // Keyframe f's bricks at `pose` for `grid` (RESOURCE_EXHAUSTED when allocating them would
  // take the map over max_map_bytes).
  absl::StatusOr<std::vector<BrickCoord>> FrameBricks(int f, const SE3& pose,
                                                      const SparseGrid& grid) const;
  void StartIntegration();
  // Runs the current phase's pieces until it ends or `deadline` passes; moves to the next.
  absl::Status AdvanceIntegration(std::chrono::steady_clock::time_point deadline);
  void StartBufferGrowth();
  void FinishIntegration();
  void ResizeOptimizerBuffers();
  GridGradView grad_view();
  OptimizerStateView state_view();

  MapperOptions options_;
  Backend* backend_;
  std::unique_ptr<PlenoxelMap> map_;
  TrainingSet training_;
  int integrated_frames_ = 0;  // keyframes whose integration is complete
  std::unique_ptr<Integration> integration_;  // the one in progress, or null
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

// Frame-to-model tracking against a frozen map (DESIGN.md §8). Each frame's pose is found by
// Gauss-Newton / Levenberg-Marquardt on the 6x6 normal equations of robust (Huber), noise-scaled
// colour and depth residuals, coarse-to-fine over the number of rays, starting from a
// constant-velocity prediction. An Adam mode follows the paper's tracker for comparison.
// Every result says whether it can be trusted (OK / DEGRADED / LOST) and why.
#pragma once

#include <algorithm>
#include <chrono>
#include <optional>
#include <string>
#include <vector>

#include "core/common/unified_allocator.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/kernels/tracking_terms.h"
#include "core/tracking/pixel_selection.h"

namespace plx {

enum class TrackingState { kOk, kDegraded, kLost };
const char* TrackingStateName(TrackingState state);

// Why a result is not OK. kFewValidRays says the map does not cover the view (unmapped space:
// the pose may still be good, and the view is what a keyframe would add); the others say the
// estimate itself is doubtful.
enum class TrackingCause { kNone, kFewValidRays, kDiverged, kHighResidual };

enum class TrackingMode { kGaussNewton, kAdam };

// The range of TrackerOptions::rays and the cap on its iterations (Tracker::ValidateOptions):
// the daemon's TrackOptions and the CLI's --rays/--iterations are held to them.
inline constexpr int kMinTrackerRays = 16;
inline constexpr int kMaxTrackerRays = 1 << 22;
inline constexpr int kMaxTrackerIterations = 10000;

struct TrackerOptions {
  TrackingMode mode = TrackingMode::kGaussNewton;
  // Rays per frame (GN: at the fine level; Adam: per iteration). GN's 2048 chosen pixels
  // track real frames better than 4096 uniform ones at half the cost (docs/BENCHMARKS.md).
  int rays = 2048;
  int iterations = 8;    // GN: total over both levels; Adam: steps (paper: 90)
  // Where the GN rays go (pixel_selection.h); Adam draws uniformly, as the paper.
  PixelSampling sampling = PixelSampling::kInformative;
  // GN coarse level: rays / coarse_divisor for the first half of the iterations, with the colour
  // noise scale multiplied by coarse_color_scale: colour residuals linearise well only within a
  // texture's width of the optimum, depth residuals much further out, so geometry brings the pose
  // in while the down-weighted colour still pins the directions depth cannot see (sliding along
  // a wall); the fine level then weighs both at their noise.
  int coarse_divisor = 4;
  float coarse_color_scale = 4.0f;
  float huber_k = 2.0f;  // in noise-scale units
  // Stretch the noise scales to the robust spread of the residuals at the start of each level
  // (never below 1), and keep them for that level so the cost stays comparable between steps.
  bool adaptive_scale = true;
  float converged_translation = 1e-4f;  // metres: stop when a step is smaller than this ...
  float converged_rotation = 1e-4f;     // ... and this (radians)
  // Bounds a frame's Gauss-Newton by time as well as by iterations: no iteration starts that
  // would end past this many milliseconds after Track began (at the pace of the level's last
  // iteration), except the fine level's first (its evaluation classifies the frame at the
  // sensor's noise). A view that puts many samples on each ray, or a CPU shared with mapping,
  // then costs fewer iterations instead of a longer frame. 0: the iterations alone bound the
  // work. Time-based: off wherever runs must repeat bit for bit.
  double time_budget_ms = 0.0;
  bool constant_velocity = true;
  TrackingParams params;

  // Adam (paper's setting: lr 1e-3, decayed by 0.8 every 10 steps).
  float adam_lr = 1e-3f;
  int adam_decay_every = 10;
  float adam_decay = 0.8f;

  // Trust. Fractions are of the rays asked for; RMS is of the noise-scaled residuals.
  float lost_valid_fraction = 0.1f;
  float degraded_valid_fraction = 0.3f;
  float degraded_rms = 2.5f;
  float lost_rms = 6.0f;
  float lost_translation = 0.5f;  // metres away from the prediction
  float lost_rotation = 0.5f;     // radians away from the prediction

  uint32_t seed = 20230606;
};

// The defaults of a mode: Gauss-Newton as above; Adam with the paper's 90 steps per frame of
// 4096 rays.
inline TrackerOptions TrackerOptionsForMode(TrackingMode mode) {
  TrackerOptions options;
  options.mode = mode;
  if (mode == TrackingMode::kAdam) {
    options.iterations = 90;
    options.rays = 4096;  // uniform draws, fresh every step
  }
  return options;
}

struct TrackingResult {
  SE3 pose;                 // world_T_camera; for LOST frames the prediction, not an estimate
  TrackingState state = TrackingState::kLost;
  std::string reason;       // why DEGRADED or LOST
  TrackingCause cause = TrackingCause::kNone;
  int iterations = 0;
  bool out_of_time = false;  // TrackerOptions::time_budget_ms ended the iterations early
  int rays = 0;             // asked for
  int valid_rays = 0;       // rendered by the map with a valid measurement
  double residual_rms = 0;  // noise-scaled
  double milliseconds = 0;
};

class Tracker {
 public:
  // `map` and `backend` must outlive the tracker (or the next set_map). The map is only read:
  // a published version shared with other readers, whose cell occupancy its publisher made
  // exact (stale occupancy is still correct, only slower).
  Tracker(const PlenoxelMap* map, Backend* backend, const TrackerOptions& options);

  static absl::Status ValidateOptions(const TrackerOptions& options);

  // Switches to another version of the map (the daemon's readers follow mapping jobs); the pose
  // and motion model carry over.
  void set_map(const PlenoxelMap* map) { map_ = map; }

  // The iteration count for the next frames (at least 1): a caller whose starting guess is
  // better than the motion model's (SLAM's odometry) needs less of the schedule.
  void set_iterations(int iterations) { options_.iterations = std::max(1, iterations); }
  // TrackerOptions::time_budget_ms for the next frames (0: none).
  void set_time_budget_ms(double ms) { options_.time_budget_ms = std::max(0.0, ms); }

  // Starts from a known pose (e.g. the first frame's ground truth) at `timestamp`.
  void Reset(const SE3& world_T_camera, double timestamp);
  // The world's frame changed (a loop closure's correction): the last pose moves by
  // new_T_old; the motion model (a velocity in the camera's frame) carries over.
  void MoveWorld(const SE3& new_T_old) { last_pose_ = new_T_old * last_pose_; }

  // Tracks one frame. `prior` (e.g. a headset's VIO pose) replaces the constant-velocity
  // prediction as the initial guess. Errors are the backend's (device, memory), not the
  // frame's: a frame that cannot be tracked is a LOST result.
  absl::StatusOr<TrackingResult> Track(const RgbdFrame& frame,
                                       const PinholeIntrinsics& intrinsics,
                                       const std::optional<SE3>& prior = std::nullopt);

  // The constant-velocity prediction at `timestamp` from the last frame tracked (not LOST):
  // the last pose when there is no motion model or the gap is over a second.
  SE3 Predict(double timestamp) const;

 private:
  void SamplePixels(const RgbdFrame& frame, int count, PixelSampling sampling);
  // Computes the per-ray terms at `pose` and sums them with the noise stretched by `scale`
  // (colour, depth); when `estimate_scale` is set, first replaces `scale` by the robust spread.
  absl::StatusOr<TrackingSums> Evaluate(const SE3& pose, const RgbdFrame& frame,
                                        const PinholeIntrinsics& k, int rays, TrackingLoss loss,
                                        float scale[2], bool estimate_scale);
  // `start`: when Track began; the time budget counts from there (the pixel selection too), as
  // TrackingResult::milliseconds does.
  absl::Status RunGaussNewton(const RgbdFrame& frame, const PinholeIntrinsics& k,
                              std::chrono::steady_clock::time_point start, SE3* pose,
                              TrackingResult* result, TrackingSums* last);
  absl::Status RunAdam(const RgbdFrame& frame, const PinholeIntrinsics& k, SE3* pose,
                       TrackingResult* result, TrackingSums* last);
  void RobustScales(int rays, float scale[2]);
  void Classify(const SE3& predicted, const TrackingSums& last, TrackingResult* result) const;

  const PlenoxelMap* map_;
  Backend* backend_;
  TrackerOptions options_;
  SE3 last_pose_;
  double last_timestamp_ = 0.0;
  std::optional<Vector6d> velocity_;  // tangent of the last motion, per second
  uint32_t frame_counter_ = 0;
  PixelSelectionScratch selection_scratch_;
  UnifiedVector<int32_t> pixels_;          // read by the backend
  UnifiedVector<TrackingRayTerm> terms_;   // written by the backend
  std::vector<float> scratch_;
};

}  // namespace plx

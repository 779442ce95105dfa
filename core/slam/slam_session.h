// Online RGB-D SLAM (DESIGN.md §9): unposed frames in, one pose per frame out while the map
// grows behind the tracker.
//
//   - Bootstrap: the first frame becomes keyframe 0 at the initial pose (the caller's, its prior,
//     or the identity) and the first map version is built from its depth. A session that
//     continues an existing map instead tracks its first frame in that map from the initial pose.
//   - Tracking: every frame against the latest published map version with the frame-to-model
//     tracker (constant-velocity prediction, or the caller's prior, e.g. a headset's VIO pose).
//   - Keyframes: by motion and by how much of the view the map does not render yet
//     (core/slam/keyframe_policy.h). Only frames tracked OK become keyframes; LOST frames are
//     never integrated.
//   - Mapping: a MappingSession over the keyframes, with a local window (half of each batch from
//     the last keyframes, half from all of them). By default it runs on its own thread with its
//     own backend, at a lower CPU priority so that tracking keeps its latency; deterministic mode
//     runs it in lock-step on the caller's thread after each keyframe instead (bit-identical
//     results run to run, for tests).
//   - Keyframe pose refinement: after each new keyframe's mapping, the keyframes of the window
//     (never keyframe 0, which fixes the gauge) are re-aligned to the published map with the
//     tracking equations, alternating with the map optimisation (core/slam/keyframe_refinement.h).
//   - Relocalisation: after a LOST frame each new frame is tried from the last good pose and from
//     the nearest keyframe poses; the first that tracks OK is reported RELOCALISED. Until then
//     frames report LOST with the prediction, never an unconverged estimate.
//
// Memory grows with the number of keyframes (their images and rays: ~16 B per pixel plus 8 B
// per pixel with valid depth, 7.4 MB for a 640x480 keyframe) and with the mapped volume (the
// grid), not with the number of frames.
//
// Threads: one caller at a time (ProcessFrame, Finish); progress(), latest_map() and
// keyframe_poses() from any thread.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapping_session.h"
#include "core/slam/keyframe_policy.h"
#include "core/slam/keyframe_refinement.h"
#include "core/tracking/tracker.h"

namespace plx {

enum class SlamState { kOk, kDegraded, kLost, kRelocalised };
const char* SlamStateName(SlamState state);

struct SlamOptions {
  TrackerOptions tracker;
  MappingSessionOptions mapping;
  KeyframePolicy keyframes;
  KeyframeRefinementOptions refinement;  // refinement.window = 0 turns it off

  // Lock-step mapping on the caller's thread (see above). Bit-identical results also need a
  // mapping backend whose gradient scatter has a fixed order: the CPU backend on one thread
  // (with more, atomic float adds land in a varying order).
  bool deterministic = false;
  // Concurrent mode: the mapping thread's nice increment (Linux; 0 = same priority as the
  // tracker). Its backend's worker threads inherit it.
  int mapping_nice = 10;

  // Keyframe poses tried besides the last good pose when relocalising.
  int relocalisation_keyframes = 4;
  // An attempt that ends further than this from its starting pose is a false match.
  double relocalisation_radius_m = 0.25;

  // Where keyframe 0 sits (world_T_camera); the frame's prior wins, else the identity.
  std::optional<SE3> initial_pose;
};

// The defaults SLAM uses: the mapping window on, publishing every 0.25 s at most.
SlamOptions DefaultSlamOptions();

// InvalidArgument naming the field.
absl::Status ValidateSlamOptions(const SlamOptions& options);

struct SlamFrameResult {
  int frame = 0;  // 0-based count of frames given to the session
  double timestamp = 0.0;
  SE3 pose;       // world_T_camera; for LOST frames the prediction
  SlamState state = SlamState::kLost;
  std::string reason;  // why DEGRADED / LOST, how it relocalised, or what made a keyframe
  bool keyframe = false;
  int keyframes = 0;            // keyframes accepted so far, this one included
  int64_t map_version = 0;      // the published version the frame was tracked against
  TrackingResult tracking;      // rays, iterations, residual of the accepted estimate
  double milliseconds = 0.0;    // ProcessFrame's time (deterministic mode: mapping included)
};

struct SlamProgress {
  int frames = 0;
  int keyframes = 0;              // accepted
  int keyframes_integrated = 0;   // by mapping
  int pending_keyframes = 0;      // accepted, not yet integrated (mapping lag)
  int ok = 0, degraded = 0, lost = 0, relocalised = 0;
  int mapping_iterations = 0;
  int refined_keyframes = 0;      // pose updates applied by refinement
  int64_t map_version = 0;
  int64_t map_bytes = 0;
  int64_t keyframe_bytes = 0;     // images and ray lists kept for mapping
};

class SlamSession {
 public:
  using BackendFactory = std::function<absl::StatusOr<std::unique_ptr<Backend>>()>;

  // `tracking_backend` must outlive the session. `make_mapping_backend` is called once, on the
  // mapping thread (concurrent mode) or here (deterministic mode). `base`: an existing map to
  // extend (shared, never written), or null for a new one.
  static absl::StatusOr<std::unique_ptr<SlamSession>> Create(
      const SlamOptions& options, Backend* tracking_backend,
      const BackendFactory& make_mapping_backend,
      std::shared_ptr<const PlenoxelMap> base = nullptr);
  ~SlamSession();  // abandons mapping work not finished (call Finish to keep it)

  SlamSession(const SlamSession&) = delete;
  SlamSession& operator=(const SlamSession&) = delete;

  // Tracks one frame and hands it to mapping when it makes a keyframe. Errors are the
  // backend's, the mapping thread's or bad input (sizes, non-finite prior): a frame that cannot
  // be tracked is a LOST result.
  absl::StatusOr<SlamFrameResult> ProcessFrame(RgbdFrame frame, const PinholeIntrinsics& k,
                                               const std::optional<SE3>& prior = std::nullopt);

  // Takes no more frames; mapping integrates the keyframes accepted, spends their iteration
  // budget and publishes the final version.
  absl::Status Finish();

  std::shared_ptr<const PlenoxelMap> latest_map() const;
  // Keyframe poses as refined so far (timestamp, world_T_camera), in keyframe order.
  std::vector<StampedPose> keyframe_poses() const;
  SlamProgress progress() const;

 private:
  SlamSession(const SlamOptions& options, Backend* tracking_backend);

  absl::Status StartMapping(const BackendFactory& make_backend,
                            std::shared_ptr<const PlenoxelMap> base);
  void MappingLoop(const BackendFactory& make_backend, std::shared_ptr<const PlenoxelMap> base,
                   std::promise<absl::Status>* started);
  // Runs steps until the session has no work, then publishes (deterministic mode, Finish).
  absl::Status RunMappingToEnd(bool finish);
  // Publishes what the last steps changed and records it (AfterStep).
  absl::Status PublishIfChanged();
  // Records a step's result: a new version, progress, refinement. Mapping thread / lock-step.
  absl::Status AfterStep(const MappingStepResult& step);
  absl::Status AddKeyframe(const RgbdFrame& frame, const SE3& pose, const PinholeIntrinsics& k);
  absl::StatusOr<std::optional<TrackingResult>> Relocalise(const RgbdFrame& frame,
                                                            const PinholeIntrinsics& k,
                                                            const std::optional<SE3>& prior);
  absl::Status WaitForFirstVersion();
  absl::Status MappingError() const;

  const SlamOptions options_;
  Backend* tracking_backend_;
  Tracker tracker_;
  std::shared_ptr<const PlenoxelMap> tracked_map_;  // keeps the tracker's version alive
  int64_t tracked_version_ = 0;

  // Tracking thread state.
  int frames_ = 0;
  bool lost_ = false;
  std::optional<SE3> last_good_pose_;
  std::vector<StampedPose> accepted_keyframes_;  // poses as accepted (the policy's view)
  int keyframes_ = 0;
  bool finished_ = false;

  // Mapping: owned by the mapping thread in concurrent mode, by the caller in lock-step mode.
  std::unique_ptr<Backend> mapping_backend_;
  std::unique_ptr<MappingSession> mapping_;
  int refined_upto_keyframes_ = 0;  // integrated keyframes the last refinement saw
  std::thread mapping_thread_;

  mutable std::mutex mutex_;  // guards what follows
  std::condition_variable changed_;
  std::shared_ptr<const PlenoxelMap> latest_;
  int64_t version_ = 0;
  bool stop_ = false;        // leave now
  bool finishing_ = false;   // leave once the work is done
  bool mapping_done_ = false;
  uint64_t wakeups_ = 0;     // bumped when a keyframe is queued
  absl::Status mapping_error_;
  std::vector<StampedPose> keyframe_poses_;
  SlamProgress progress_;    // mapping-side fields
};

}  // namespace plx

// The tracking half of SLAM for one camera (DESIGN.md §9): each frame against the latest
// published version of the map, the keyframe decision, and relocalisation after LOST. It never
// writes the map: a frame it marks as a keyframe is handed to the map's SlamMapper by the
// caller (SlamSession in-process; the daemon's Slam stream), so several cameras can track in
// one map that one mapper grows.
//
//   - Bootstrap: with no map yet, the first frame is keyframe 0 at the initial pose (the
//     frame's prior, else SlamTrackerOptions::initial_pose, else the identity).
//   - Tracking: constant-velocity prediction, or the caller's prior (e.g. a headset's VIO).
//   - Keyframes: only frames tracked OK, by the policy (core/slam/keyframe_policy.h) against
//     every keyframe the map has accepted.
//   - Relocalisation: after a LOST frame (or, when `start_lost`, from the first frame: a camera
//     joining an existing map) each frame is tried from the prior, the motion model's
//     prediction, the last good pose and the nearest keyframes; the first that tracks OK, stays
//     near its start and passes a check at the sensor's noise is RELOCALISED. Until then
//     frames are LOST with the prediction, never an unconverged estimate.
//
// Threads: one caller at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/slam/keyframe_policy.h"
#include "core/tracking/tracker.h"

namespace plx {

enum class SlamState { kOk, kDegraded, kLost, kRelocalised };
const char* SlamStateName(SlamState state);

struct SlamTrackerOptions {
  TrackerOptions tracker;
  KeyframePolicy keyframes;
  // Keyframe poses tried besides the last good pose when relocalising.
  int relocalisation_keyframes = 4;
  // An attempt that ends further than this from its starting pose is a false match.
  double relocalisation_radius_m = 0.25;
  // Where the camera starts (world_T_camera); the first frame's prior wins, else the identity.
  std::optional<SE3> initial_pose;
};

absl::Status ValidateSlamTrackerOptions(const SlamTrackerOptions& options);

// What a camera sees of the map when it tracks a frame (SlamMapper's accessors, read once).
struct SlamMapView {
  std::shared_ptr<const PlenoxelMap> map;  // the latest published version (null: none yet)
  int64_t version = 0;
  std::vector<StampedPose> accepted_keyframes;  // for the keyframe policy
  std::vector<StampedPose> keyframe_poses;      // refined, for relocalisation
  // Keyframes wait for integration: the part of the view the map does not render yet is
  // mostly what they will fill in, so it does not count towards a keyframe.
  bool mapping_behind = false;
};

struct SlamFrameResult {
  int frame = 0;  // 0-based count of frames given to this camera
  double timestamp = 0.0;
  SE3 pose;       // world_T_camera; for LOST frames the prediction
  SlamState state = SlamState::kLost;
  std::string reason;  // why DEGRADED / LOST, how it relocalised, or what made a keyframe
  bool keyframe = false;        // the caller hands this frame to the mapper
  int keyframes = 0;            // keyframes accepted so far, this one included
  int64_t map_version = 0;      // the published version the frame was tracked against
  TrackingResult tracking;      // rays, iterations, residual of the accepted estimate
  double milliseconds = 0.0;    // tracking time (SlamSession: the whole ProcessFrame)
};

// Per-camera counts.
struct SlamTrackerCounts {
  int frames = 0;
  int ok = 0, degraded = 0, lost = 0, relocalised = 0;
};

class SlamTracker {
 public:
  // `backend` must outlive the tracker. `start_lost`: the camera joins an existing map and its
  // first frame has to find itself in it (a relocalisation from the initial pose or prior).
  SlamTracker(const SlamTrackerOptions& options, Backend* backend, bool start_lost);

  // Checks the frame against `k` and a prior for finiteness (InvalidArgument naming the frame).
  absl::Status CheckFrame(const RgbdFrame& frame, const PinholeIntrinsics& k,
                          const std::optional<SE3>& prior) const;

  // Tracks one frame in `view` (checked with CheckFrame first). Errors are the backend's; a
  // frame that cannot be tracked is a LOST result. The first frame of a map with neither a
  // version nor an accepted keyframe is the bootstrap keyframe (one camera must bootstrap a
  // map: the caller serialises that); any other frame while the map has no version yet is
  // FailedPrecondition, with nothing changed (hand the frame in again once a version is out).
  // `result.keyframes` counts view.accepted_keyframes plus this one.
  absl::StatusOr<SlamFrameResult> Track(const RgbdFrame& frame, const PinholeIntrinsics& k,
                                        const std::optional<SE3>& prior,
                                        const SlamMapView& view);

  const SlamTrackerCounts& counts() const { return counts_; }
  int frames() const { return counts_.frames; }

 private:
  absl::StatusOr<std::optional<TrackingResult>> Relocalise(const RgbdFrame& frame,
                                                            const PinholeIntrinsics& k,
                                                            const std::optional<SE3>& prior,
                                                            const SlamMapView& view);

  const SlamTrackerOptions options_;
  Backend* const backend_;
  Tracker tracker_;
  std::shared_ptr<const PlenoxelMap> tracked_map_;  // keeps the tracker's version alive
  bool lost_ = false;
  std::optional<SE3> last_good_pose_;
  SlamTrackerCounts counts_;
};

}  // namespace plx

// How the SLAM front-end turns its two estimates of a frame's pose into one (docs/SLAM.md,
// "Front-end"): the map tracker's (absolute, drift-free, but only where the map renders the
// view) and the map-free odometry's (relative to the previous frame, so it drifts slowly, but it
// works in unmapped space and across motions too large for the map tracker's basin, whose
// starting point it gives).
//
//   map tracker        odometry   pose              state     may be a keyframe
//   OK                 OK or none map               OK        yes (keyframe policy)
//   OK, jumped away    OK         odometry          DEGRADED  no: as "diverged" below
//   from the odometry
//   OK                 failed     map               OK        only once confirmed: the motion
//                                                             is unknown (a jump, a blur), and
//                                                             the map tracker can settle on a
//                                                             wrong pose that it explains well
//                                                             (`confirm`: SlamTracker checks it
//                                                             against the keyframes' features)
//   few rays, agrees   OK         map               DEGRADED  yes: the view is unmapped, the
//   few rays           OK         odometry          DEGRADED  yes  pose is sure: exactly when
//                                                                  the map needs a keyframe
//   diverged/residual  OK         odometry          DEGRADED  no: the map and the frame
//                                                                  disagree; only once the
//                                                                  keyframes' features confirm
//                                                                  the odometry's pose (the map
//                                                                  lags the view: SlamTracker)
//   DEGRADED           not OK     map               DEGRADED  no
//   LOST               not OK     prediction        LOST      no
//
// "Agrees": within PoseFusionOptions of the odometry's pose. A map estimate from few rays is
// absolute (it does not drift) but can slide along the little it sees; when it stays near the
// odometry's it is the better of the two.
#pragma once

#include <optional>
#include <string>

#include "core/geometry/se3.h"
#include "core/slam/slam_state.h"
#include "core/tracking/tracker.h"

namespace plx {

enum class PoseSource { kMap, kOdometry, kPrediction };
const char* PoseSourceName(PoseSource source);

struct PoseFusionOptions {
  double agree_translation_m = 0.05;
  double agree_rotation_rad = 0.05;  // ~3 degrees
  // An OK map pose further than this from a trusted odometry's (which started the map
  // tracker) is a jump to another basin, not the drift the map corrects: the odometry's
  // relative motion is good to millimetres, its drift over the frames it carried alone
  // centimetres. In a live-camera replay of the two rooms, after 17 frames the map tracker
  // diverged on, it came back OK 26 cm from the odometry's pose, 33 cm from the truth, and
  // took a keyframe there (docs/BENCHMARKS.md). Such a frame is the odometry's, DEGRADED, and
  // the keyframes' features decide (SlamTracker): they move it where they and the map agree
  // (a real snap back after a long carry), or confirm the odometry's pose.
  double max_map_jump_m = 0.10;
  double max_map_jump_rad = 0.10;  // ~6 degrees
};

// The odometry's estimate of the frame's pose in the world (previous pose times the relative
// motion) when it was trusted.
struct OdometryPose {
  SE3 pose;
  bool ok = false;
  std::string reason;  // why not ok
};

struct FusedPose {
  SE3 pose;
  SlamState state = SlamState::kLost;
  std::string reason;
  PoseSource source = PoseSource::kPrediction;
  bool may_be_keyframe = false;
  // The pose is the map's but nothing independent backs it (the odometry failed): the caller
  // confirms it (relocalisation by features) before it may be a keyframe.
  bool confirm = false;
};

// A fused pose after the keyframes' features were asked about it (SlamTracker does so when
// FusedPose::confirm is set, or when the map contradicts the odometry's pose) and did not move
// the frame elsewhere:
//   - confirm, the features agree: OK, may be a keyframe;
//   - confirm, they do not (nothing found, or a place the dense check refused): DEGRADED, never
//     a keyframe;
//   - the map contradicted the odometry, the features agree with the odometry: two independent
//     estimates place the frame and only the map does not explain it there, so the map lags
//     the view (geometry still converging, colour that does not fit yet), which is what a
//     keyframe fixes: still DEGRADED (the map does not explain it), but it may be a keyframe.
//     Without this a camera whose view the map renders poorly never adds the keyframe that
//     would make it render well (teddy at every 3rd frame: 32 of 42 frames DEGRADED by
//     residual, 3 keyframes);
//   - the map contradicted the odometry, no agreement: as fused (DEGRADED, no keyframe).
struct CheckedPose {
  SlamState state = SlamState::kDegraded;
  bool may_be_keyframe = false;
  std::string reason;
  // A pose to confirm that the features did not: the next frames' poses, which follow from
  // it, need confirming too (ChainedToUnconfirmedPose).
  bool unconfirmed = false;
};
CheckedPose ApplyFeatureCheck(const FusedPose& fused, bool features_found, bool features_agree);

// A frame whose pose follows from an earlier map pose the features did not confirm (the
// odometry is relative to it, and the map tracker starts there): the earlier pose may be a
// wrong place the map explains (after a jump in the stream, the map tracker can settle tens of
// centimetres off on a view it explains well) and every pose chained to it then is as wrong,
// tracked OK frame after frame. Such a frame needs the same confirmation as the first one
// (`confirm`), and is no keyframe before it (a keyframe there would fuse the view at the wrong
// place). SlamTracker keeps the chain unconfirmed until the features agree with a pose of it or
// move the camera to a place they and the map verify.
FusedPose ChainedToUnconfirmedPose(FusedPose fused);

// Whether two estimates of a frame's pose are the same within the options' tolerances.
bool PosesAgree(const SE3& a, const SE3& b, const PoseFusionOptions& options);

// `map`: the map tracker's result (its pose is the prediction when LOST); `odometry`: absent
// when there was nothing to align to (the first frame, or the previous one was LOST).
FusedPose FusePoses(const TrackingResult& map, const std::optional<OdometryPose>& odometry,
                    const PoseFusionOptions& options);

}  // namespace plx

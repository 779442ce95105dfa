// How much of a camera's motion between two keyframes the map did not confirm: the frames
// tracked otherwise than OK (carried by the odometry alone, relocalised, lost) moved the pose
// on evidence that drifts or jumps. The tracker sums it per keyframe (SlamFrameResult::
// unconfirmed) and loop closure widens the pose graph's sequential edge into that keyframe by
// it (LoopClosureOptions::unconfirmed_sigma_per_m), so a loop's correction goes where tracking
// was unsure rather than evenly over every metre.
#pragma once

#include "core/geometry/se3.h"

namespace plx {

struct UnconfirmedMotion {
  double m = 0.0;    // metres the camera centre moved on unconfirmed frames
  double rad = 0.0;  // radians it turned on them

  // Adds a frame that moved the camera from `before` to `after` (both world_T_camera).
  void Add(const SE3& before, const SE3& after) {
    m += (after.translation() - before.translation()).norm();
    rad += RotationAngleBetween(before, after);
  }
};

}  // namespace plx

// A loop closure's correction of a map's frame of reference (docs/SLAM.md, "Loop closure").
// When the pose graph moves the keyframes, the map is rebuilt at the new poses and published as
// one version; from that version on, every pose in the map's frame is a corrected one. Anything
// a camera or a client holds in the old frame (its pose, its motion model's origin, a headset's
// anchors) moves with the keyframe it is anchored to (NearestKeyframe): a pose p anchored to
// keyframe i becomes after[i] * before[i]^-1 * p. The correction is rigid per keyframe, not
// per map: the start of a loop barely moves, its end moves most.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"

namespace plx {

struct SlamCorrection {
  int generation = 0;       // 1, 2, ...: the map's corrections so far, this one included
  int64_t map_version = 0;  // the first published version in the corrected frame
  // Every keyframe's pose in the frame before and after, in keyframe order.
  std::vector<SE3> before, after;
  double max_shift_m = 0.0;  // the largest keyframe translation
  double solve_ms = 0.0;     // the pose-graph solve that made it
  int loops = 0;             // loop edges in that solve

  // The keyframe `pose` (in the old frame) is anchored to: the newest of the keyframes within
  // kRecentKeyframeMargin of the nearest (distance: metres of position plus radians of viewing
  // direction); -1 when there is none.
  static constexpr double kRecentKeyframeMargin = 0.3;
  int NearestKeyframe(const SE3& pose) const;
  // `pose` (in the old frame) in the corrected frame, moved with its keyframe.
  SE3 Move(const SE3& pose) const;
  // new_T_old at `pose`: what Move left-multiplies it by.
  SE3 FrameChangeAt(const SE3& pose) const;
};

// The new_T_old each of `corrections` (in order, each after the one before) makes at a pose
// that starts as `pose` in the frame before the first and is moved by each in turn: the
// camera_new_T_old of each for a camera whose last pose was `pose` and that followed none.
std::vector<SE3> FrameChangesAlong(
    const std::vector<std::shared_ptr<const SlamCorrection>>& corrections, SE3 pose);

// The same rule over a map's keyframes as they are now (SlamMapView::keyframe_poses): the
// keyframe a pose tracked now is anchored to, should a later correction move it (-1: none).
int AnchorKeyframe(const std::vector<StampedPose>& keyframes, const SE3& pose);

}  // namespace plx

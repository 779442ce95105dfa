#include "core/slam/slam_correction.h"

#include <algorithm>
#include <limits>
#include <vector>

namespace plx {

namespace {

// The anchor rule over the first `n` keyframes, `keyframe(i)` giving keyframe i's pose.
template <typename KeyframePose>
int AnchorAmong(size_t n, const KeyframePose& keyframe, const SE3& pose) {
  std::vector<double> distance(n);
  double nearest = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; ++i) {
    const SE3& k = keyframe(i);
    distance[i] = (k.translation() - pose.translation()).norm() + RotationAngleBetween(k, pose);
    nearest = std::min(nearest, distance[i]);
  }
  // The newest of those about as near as the nearest: a camera walks on from the keyframes it
  // made last, and where it revisits a place before the loop is closed its pose agrees with
  // those (the drifted chain), not with the older ones there.
  for (size_t i = n; i-- > 0;) {
    if (distance[i] <= nearest + SlamCorrection::kRecentKeyframeMargin) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

}  // namespace

std::vector<SE3> FrameChangesAlong(
    const std::vector<std::shared_ptr<const SlamCorrection>>& corrections, SE3 pose) {
  std::vector<SE3> changes;
  for (const std::shared_ptr<const SlamCorrection>& c : corrections) {
    changes.push_back(c->FrameChangeAt(pose));
    pose = changes.back() * pose;
  }
  return changes;
}

int AnchorKeyframe(const std::vector<StampedPose>& keyframes, const SE3& pose) {
  return AnchorAmong(
      keyframes.size(), [&](size_t i) -> const SE3& { return keyframes[i].pose; }, pose);
}

int SlamCorrection::NearestKeyframe(const SE3& pose) const {
  return AnchorAmong(
      std::min(before.size(), after.size()), [&](size_t i) -> const SE3& { return before[i]; },
      pose);
}

SE3 SlamCorrection::FrameChangeAt(const SE3& pose) const {
  const int i = NearestKeyframe(pose);
  return i < 0 ? SE3::Identity() : after[i] * before[i].Inverse();
}

SE3 SlamCorrection::Move(const SE3& pose) const { return FrameChangeAt(pose) * pose; }

}  // namespace plx

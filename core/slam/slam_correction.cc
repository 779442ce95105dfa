#include "core/slam/slam_correction.h"

#include <algorithm>
#include <limits>
#include <vector>

namespace plx {

int SlamCorrection::NearestKeyframe(const SE3& pose) const {
  const size_t n = std::min(before.size(), after.size());
  std::vector<double> distance(n);
  double nearest = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; ++i) {
    distance[i] = (before[i].translation() - pose.translation()).norm() +
                  RotationAngleBetween(before[i], pose);
    nearest = std::min(nearest, distance[i]);
  }
  // The newest of those about as near as the nearest: a camera walks on from the keyframes it
  // made last, and where it revisits a place before the loop is closed its pose agrees with
  // those (the drifted chain), not with the older ones there.
  for (size_t i = n; i-- > 0;) {
    if (distance[i] <= nearest + kRecentKeyframeMargin) return static_cast<int>(i);
  }
  return -1;
}

SE3 SlamCorrection::FrameChangeAt(const SE3& pose) const {
  const int i = NearestKeyframe(pose);
  return i < 0 ? SE3::Identity() : after[i] * before[i].Inverse();
}

SE3 SlamCorrection::Move(const SE3& pose) const { return FrameChangeAt(pose) * pose; }

}  // namespace plx

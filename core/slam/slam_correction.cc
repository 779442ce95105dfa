#include "core/slam/slam_correction.h"

#include <limits>

namespace plx {

int SlamCorrection::NearestKeyframe(const SE3& pose) const {
  int best = -1;
  double best_distance = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < before.size() && i < after.size(); ++i) {
    const double d = (before[i].translation() - pose.translation()).norm() +
                     RotationAngleBetween(before[i], pose);
    if (d < best_distance) best_distance = d, best = static_cast<int>(i);
  }
  return best;
}

SE3 SlamCorrection::FrameChangeAt(const SE3& pose) const {
  const int i = NearestKeyframe(pose);
  return i < 0 ? SE3::Identity() : after[i] * before[i].Inverse();
}

SE3 SlamCorrection::Move(const SE3& pose) const { return FrameChangeAt(pose) * pose; }

}  // namespace plx

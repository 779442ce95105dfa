// A pose with the time it was taken: ground truth read from a dataset, a trajectory file row or
// a tracker's estimate. Lives with SE3 rather than with any one reader so that tracking,
// evaluation and the trajectory formats can share it without depending on a dataset.
#pragma once

#include "core/geometry/se3.h"

namespace plx {

struct StampedPose {
  double timestamp = 0.0;  // seconds
  SE3 pose;                // world_T_camera
};

}  // namespace plx

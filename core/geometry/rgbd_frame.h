// One RGB-D observation: registered colour and depth, plus the ground-truth pose when known.
// A frame carries no estimate: a tracker's output, a client's prior and a keyframe's pose
// travel beside it (a tracking result, Tracker::Track's prior, Mapper::AddKeyframe's pose).
#pragma once

#include <optional>

#include "core/geometry/image.h"
#include "core/geometry/se3.h"

namespace plx {

struct RgbdFrame {
  double timestamp = 0.0;  // seconds
  ColorImage color;        // RGB in [0, 1]
  DepthImage depth;        // z-depth in metres, 0 = no measurement
  // The dataset's ground-truth world_T_camera, when it has one; never an estimate.
  std::optional<SE3> ground_truth;
};

}  // namespace plx

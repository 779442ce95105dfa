// One RGB-D observation: registered colour and depth, plus the ground-truth pose when known.
#pragma once

#include <optional>

#include "core/geometry/image.h"
#include "core/geometry/se3.h"

namespace plx {

struct RgbdFrame {
  double timestamp = 0.0;  // seconds
  ColorImage color;        // RGB in [0, 1]
  DepthImage depth;        // z-depth in metres, 0 = no measurement
  std::optional<SE3> world_T_camera;  // ground truth, when the dataset has it
};

}  // namespace plx

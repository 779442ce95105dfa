// Axial noise of a depth sensor as a function of depth. Structured-light and stereo sensors
// get noisier with the square of the distance (disparity quantisation); the defaults follow the
// Kinect model of Nguyen et al. (3DIMPVT 2012): sigma(z) = 1.2 mm + 1.9 mm * (z - 0.4 m)^2.
// Mapping sizes its surface band and truncation with it, so far, noisy walls are fused over a
// band wide enough to average their noise instead of being clipped into holes.
#pragma once

#include "core/common/host_device.h"

namespace plx {

struct DepthNoiseModel {
  float constant = 0.0012f;    // metres
  float quadratic = 0.0019f;   // metres per metre^2
  float offset = 0.4f;         // metres; no growth below this depth

  PLX_HD float Sigma(float z) const {
    const float d = z > offset ? z - offset : 0.0f;
    return constant + quadratic * d * d;
  }
};

}  // namespace plx

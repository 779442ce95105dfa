// Total variation of a field at one vertex, over its differences to the +x, +y, +z neighbours
// (Plenoxels' regulariser), and its gradient.
#pragma once

#include <cmath>

#include "core/common/host_device.h"

namespace plx {

// d/dv of lambda * sqrt(dx^2 + dy^2 + dz^2 + eps) for the differences to the +x, +y, +z
// neighbours of one vertex; `values` are centre, +x, +y, +z; writes the 4 partials.
PLX_HD void TvGradient(const float values[4], float lambda, float grads[4]) {
  const float dx = values[1] - values[0], dy = values[2] - values[0], dz = values[3] - values[0];
  const float norm = sqrtf(dx * dx + dy * dy + dz * dz + 1e-9f);
  const float s = lambda / norm;
  grads[1] = s * dx;
  grads[2] = s * dy;
  grads[3] = s * dz;
  grads[0] = -(grads[1] + grads[2] + grads[3]);
}

}  // namespace plx

// Options that decide which samples a ray visits and how they composite. Forward, backward and
// tracking passes must use the same values so they walk identical samples.
#pragma once

#include "core/common/host_device.h"

namespace plx {

template <typename T>
struct RenderOptionsT {
  T step_voxels = T(0.5);            // sample spacing, in voxels (Plenoxels: half a voxel)
  T sigma_threshold = T(1e-8);       // samples with density at or below this are skipped (ReLU)
  T stop_transmittance = T(1e-4);    // stop marching once transmittance drops below this
  T near = T(0.05);                  // metres along the ray
  T far = T(12.0);                   // metres along the ray
  T background[3] = {T(0.5), T(0.5), T(0.5)};  // colour seen through empty space
};
using RenderOptions = RenderOptionsT<float>;

}  // namespace plx

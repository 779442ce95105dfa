// Trilinear interpolation over the 8 vertices of a grid cell, and its derivatives.
// Corner c (0..7) sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1): bit 0 is x.
// (fx, fy, fz) is the position inside the cell in [0, 1]^3 (voxel units).
#pragma once

#include "core/common/host_device.h"
#include "core/math/vec3.h"

namespace plx {

// Weights w[c] with sum_c w[c] v[c] = interpolated value; also d value / d v[c].
template <typename T>
PLX_HD void TrilinearWeights(const Vec3<T>& f, T w[8]) {
  const T gx = T(1) - f.x, gy = T(1) - f.y, gz = T(1) - f.z;
  w[0] = gx * gy * gz;
  w[1] = f.x * gy * gz;
  w[2] = gx * f.y * gz;
  w[3] = f.x * f.y * gz;
  w[4] = gx * gy * f.z;
  w[5] = f.x * gy * f.z;
  w[6] = gx * f.y * f.z;
  w[7] = f.x * f.y * f.z;
}

template <typename T>
PLX_HD T Trilerp(const T v[8], const T w[8]) {
  T s = T(0);
  for (int c = 0; c < 8; ++c) s += w[c] * v[c];
  return s;
}

// Spatial gradient of the interpolated field with respect to the in-cell position (per voxel
// unit; divide by the voxel size for metres). Closed form of the paper's Appendix A.
template <typename T>
PLX_HD Vec3<T> TrilinearGradient(const T v[8], const Vec3<T>& f) {
  const T gx = T(1) - f.x, gy = T(1) - f.y, gz = T(1) - f.z;
  // Differences along x on the four x-edges, blended in y and z (likewise for y and z).
  const T dx = gy * gz * (v[1] - v[0]) + f.y * gz * (v[3] - v[2]) + gy * f.z * (v[5] - v[4]) +
               f.y * f.z * (v[7] - v[6]);
  const T dy = gx * gz * (v[2] - v[0]) + f.x * gz * (v[3] - v[1]) + gx * f.z * (v[6] - v[4]) +
               f.x * f.z * (v[7] - v[5]);
  const T dz = gx * gy * (v[4] - v[0]) + f.x * gy * (v[5] - v[1]) + gx * f.y * (v[6] - v[2]) +
               f.x * f.y * (v[7] - v[3]);
  return {dx, dy, dz};
}

}  // namespace plx

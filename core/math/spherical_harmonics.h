// Real spherical-harmonic basis up to degree 2 (9 functions), the colour basis of each vertex.
// Constants and sign conventions follow Plenoxels (reference_code.md §3.3), so maps and
// numbers stay comparable with the reference implementation.
#pragma once

#include "core/common/host_device.h"
#include "core/math/vec3.h"

namespace plx {

inline constexpr int kShBasisCount = 9;
inline constexpr int kShCoeffCount = 3 * kShBasisCount;  // channel-major: c * 9 + k

// Fills basis[0..8] for the unit direction d.
template <typename T>
PLX_HD void EvalShBasis(const Vec3<T>& d, T basis[kShBasisCount]) {
  const T c0 = T(0.28209479177387814);
  const T c1 = T(0.4886025119029199);
  const T c2_0 = T(1.0925484305920792);
  const T c2_1 = T(-1.0925484305920792);
  const T c2_2 = T(0.31539156525252005);
  const T c2_3 = T(-1.0925484305920792);
  const T c2_4 = T(0.5462742152960396);
  const T x = d.x, y = d.y, z = d.z;
  basis[0] = c0;
  basis[1] = -c1 * y;
  basis[2] = c1 * z;
  basis[3] = -c1 * x;
  basis[4] = c2_0 * x * y;
  basis[5] = c2_1 * y * z;
  basis[6] = c2_2 * (T(2) * z * z - x * x - y * y);
  basis[7] = c2_3 * x * z;
  basis[8] = c2_4 * (x * x - y * y);
}

// SH DC coefficient that makes a vertex show colour `value` from every direction.
template <typename T>
PLX_HD T ShDcForColor(T value) {
  return (value - T(0.5)) / T(0.28209479177387814);
}

}  // namespace plx

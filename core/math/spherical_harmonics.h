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

namespace plx {

// d basis[k] / d d for the basis of EvalShBasis, evaluated at d (treated as a free 3-vector, so
// the caller chains through the unit-direction constraint if it needs to): grad[k][axis].
template <typename T>
PLX_HD void EvalShBasisGradient(const Vec3<T>& d, T grad[kShBasisCount][3]) {
  const T c1 = T(0.4886025119029199);
  const T c2_0 = T(1.0925484305920792);
  const T c2_1 = T(-1.0925484305920792);
  const T c2_2 = T(0.31539156525252005);
  const T c2_3 = T(-1.0925484305920792);
  const T c2_4 = T(0.5462742152960396);
  const T x = d.x, y = d.y, z = d.z;
  const T zero = T(0);
  const T g[kShBasisCount][3] = {
      {zero, zero, zero},
      {zero, -c1, zero},
      {zero, zero, c1},
      {-c1, zero, zero},
      {c2_0 * y, c2_0 * x, zero},
      {zero, c2_1 * z, c2_1 * y},
      {-T(2) * c2_2 * x, -T(2) * c2_2 * y, T(4) * c2_2 * z},
      {c2_3 * z, zero, c2_3 * x},
      {T(2) * c2_4 * x, -T(2) * c2_4 * y, zero},
  };
  for (int k = 0; k < kShBasisCount; ++k) {
    for (int a = 0; a < 3; ++a) grad[k][a] = g[k][a];
  }
}

}  // namespace plx

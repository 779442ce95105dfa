// A rigid transform for host/device math, kept apart from Vec3 so that a newcomer finds it under
// its own name. Templated on the scalar like Vec3.
#pragma once

#include "core/common/host_device.h"
#include "core/math/vec3.h"

namespace plx {

// Row-major 3x3 rotation plus translation: p_world = R * p_camera + t. Trivially copyable so it
// can be passed to kernels by value.
template <typename T>
struct RigidTransform {
  T r[9];
  T t[3];

  PLX_HD Vec3<T> Rotate(const Vec3<T>& v) const {
    return {r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
            r[6] * v.x + r[7] * v.y + r[8] * v.z};
  }
  PLX_HD Vec3<T> Apply(const Vec3<T>& v) const {
    return Rotate(v) + Vec3<T>{t[0], t[1], t[2]};
  }
  PLX_HD Vec3<T> translation() const { return {t[0], t[1], t[2]}; }
};

using RigidTransformf = RigidTransform<float>;

}  // namespace plx

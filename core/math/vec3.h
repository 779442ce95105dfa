// A small 3-vector for host/device math. Templated on the scalar so that finite-difference tests
// run the very same code in double precision.
#pragma once

#include <cmath>

#include "core/common/host_device.h"

namespace plx {

template <typename T>
struct Vec3 {
  T x, y, z;

  PLX_HD T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  PLX_HD Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  PLX_HD Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  PLX_HD Vec3 operator-() const { return {-x, -y, -z}; }
  PLX_HD Vec3 operator*(T s) const { return {x * s, y * s, z * s}; }
  PLX_HD Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
};

template <typename T>
PLX_HD Vec3<T> operator*(T s, const Vec3<T>& v) {
  return v * s;
}
template <typename T>
PLX_HD T Dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <typename T>
PLX_HD Vec3<T> Cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T>
PLX_HD T Norm(const Vec3<T>& a) {
  return sqrt(Dot(a, a));
}
template <typename T>
PLX_HD Vec3<T> Normalized(const Vec3<T>& a) {
  return a * (T(1) / Norm(a));
}

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;

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

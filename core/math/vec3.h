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

}  // namespace plx

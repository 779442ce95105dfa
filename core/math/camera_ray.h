// Pinhole rays for pixel centres (u + 0.5, v + 0.5), OpenCV axes (DESIGN.md §4).
#pragma once

#include "core/common/host_device.h"
#include "core/math/rigid_transform.h"
#include "core/math/vec3.h"

namespace plx {

// Kernel-side pinhole camera: intrinsics plus world_T_camera.
template <typename T>
struct CameraViewT {
  RigidTransform<T> world_T_camera;
  T fx, fy, cx, cy;
  int width, height;
};
using CameraView = CameraViewT<float>;

// Unnormalised camera-frame direction K^-1 [u + 0.5, v + 0.5, 1] (its z is 1).
template <typename T>
PLX_HD Vec3<T> PixelDirectionCamera(const CameraViewT<T>& cam, T u, T v) {
  return {(u + T(0.5) - cam.cx) / cam.fx, (v + T(0.5) - cam.cy) / cam.fy, T(1)};
}

// World ray of pixel (u, v): origin = camera centre, unit direction. `range_per_z` converts a
// z-depth along this pixel into a range (distance along the unit ray).
template <typename T>
PLX_HD void PixelRay(const CameraViewT<T>& cam, int u, int v, Vec3<T>* origin, Vec3<T>* dir,
                     T* range_per_z) {
  const Vec3<T> dc = PixelDirectionCamera(cam, T(u), T(v));
  const T norm = Norm(dc);
  *range_per_z = norm;
  *origin = cam.world_T_camera.translation();
  *dir = cam.world_T_camera.Rotate(dc * (T(1) / norm));
}

}  // namespace plx

// Conversions from the host geometry types (Eigen, double) to the trivially copyable float
// structs kernels take.
#pragma once

#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/math/camera_ray.h"
#include "core/math/rigid_transform.h"
#include "core/math/vec3.h"

namespace plx {

template <typename T>
RigidTransform<T> ToRigidTransform(const SE3& pose) {
  RigidTransform<T> out;
  const Eigen::Matrix3d r = pose.rotation_matrix();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out.r[3 * i + j] = static_cast<T>(r(i, j));
    out.t[i] = static_cast<T>(pose.translation()[i]);
  }
  return out;
}

inline RigidTransformf ToKernelTransform(const SE3& pose) { return ToRigidTransform<float>(pose); }
CameraView ToKernelCamera(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics);

}  // namespace plx

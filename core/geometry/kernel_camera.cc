#include "core/geometry/kernel_camera.h"

namespace plx {

RigidTransformf ToKernelTransform(const SE3& pose) {
  RigidTransformf out;
  const Eigen::Matrix3d r = pose.rotation_matrix();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out.r[3 * i + j] = static_cast<float>(r(i, j));
    out.t[i] = static_cast<float>(pose.translation()[i]);
  }
  return out;
}

CameraView ToKernelCamera(const SE3& world_T_camera, const PinholeIntrinsics& k) {
  CameraView cam;
  cam.world_T_camera = ToKernelTransform(world_T_camera);
  cam.fx = static_cast<float>(k.fx);
  cam.fy = static_cast<float>(k.fy);
  cam.cx = static_cast<float>(k.cx);
  cam.cy = static_cast<float>(k.cy);
  cam.width = k.width;
  cam.height = k.height;
  return cam;
}

}  // namespace plx

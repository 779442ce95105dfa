#include "core/geometry/kernel_camera.h"

namespace plx {

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

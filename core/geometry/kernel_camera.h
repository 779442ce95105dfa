// Conversions from the host geometry types (Eigen, double) to the trivially copyable float
// structs kernels take.
#pragma once

#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/math/camera_ray.h"
#include "core/math/vec3.h"

namespace plx {

RigidTransformf ToKernelTransform(const SE3& pose);
CameraView ToKernelCamera(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics);

}  // namespace plx

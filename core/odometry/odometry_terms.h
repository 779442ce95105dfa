// What one point of the current frame contributes to the odometry's normal equations: its
// intensity and depth residuals against the reference frame and their derivatives with respect
// to reference_T_current under the right perturbation (core/math/pose_jacobian.h). Written for
// host and device (PLX_HD) like the map tracker's per-ray terms, so the same code can run as a
// kernel; today the odometry runs it on the host (core/odometry/rgbd_odometry.h says why).
#pragma once

#include <cmath>

#include "core/common/host_device.h"
#include "core/math/depth_noise.h"
#include "core/math/pose_jacobian.h"
#include "core/math/rigid_transform.h"
#include "core/math/vec3.h"

namespace plx {

// A pyramid level's images as the term reads them (row-major, width * height).
struct OdometryLevelView {
  int width = 0, height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  const float* intensity = nullptr;
  const float* intensity_du = nullptr;
  const float* intensity_dv = nullptr;
  const float* depth = nullptr;
  const float* depth_du = nullptr;
  const float* depth_dv = nullptr;
  const unsigned char* depth_smooth = nullptr;
};

struct OdometryPointTerm {
  // reference - current: the reference's intensity where the point lands minus the point's own;
  // the reference's depth there minus the point's depth in the reference camera.
  float intensity_residual = 0.0f;
  float depth_residual = 0.0f;
  float intensity_jacobian[6] = {};
  float depth_jacobian[6] = {};
  float depth_sigma = 0.0f;    // the sensor's noise at the point's depth in the reference
  bool has_intensity = false;  // the point lands inside the reference image
  bool has_depth = false;      // ... on smooth valid depth there
};

// `q`: the point in the current camera (metres), `intensity` its intensity there.
PLX_HD OdometryPointTerm ComputeOdometryTerm(const OdometryLevelView& ref,
                                             const RigidTransformf& reference_T_current,
                                             const Vec3f& q, float intensity,
                                             const DepthNoiseModel& noise) {
  OdometryPointTerm term;
  const Vec3f p = reference_T_current.Apply(q);
  if (!(p.z > 1e-3f)) return term;
  const float inv_z = 1.0f / p.z;
  // Continuous image coordinates, then the pixel grid (centres at +0.5).
  const float x = ref.fx * p.x * inv_z + ref.cx;
  const float y = ref.fy * p.y * inv_z + ref.cy;
  const float px = x - 0.5f, py = y - 0.5f;
  if (!(px >= 0.0f && py >= 0.0f && px < ref.width - 1 && py < ref.height - 1)) return term;
  const int u0 = static_cast<int>(px), v0 = static_cast<int>(py);
  const float a = px - u0, b = py - v0;
  const int i00 = v0 * ref.width + u0, i10 = i00 + 1, i01 = i00 + ref.width, i11 = i01 + 1;
  const float w00 = (1 - a) * (1 - b), w10 = a * (1 - b), w01 = (1 - a) * b, w11 = a * b;
  auto sample = [&](const float* img) {
    return w00 * img[i00] + w10 * img[i10] + w01 * img[i01] + w11 * img[i11];
  };
  // d(x, y)/dp for the pinhole projection.
  const Vec3f dx_dp{ref.fx * inv_z, 0.0f, -ref.fx * p.x * inv_z * inv_z};
  const Vec3f dy_dp{0.0f, ref.fy * inv_z, -ref.fy * p.y * inv_z * inv_z};

  term.has_intensity = true;
  term.intensity_residual = sample(ref.intensity) - intensity;
  const Vec3f g_intensity = dx_dp * sample(ref.intensity_du) + dy_dp * sample(ref.intensity_dv);
  PointGradientToPose(reference_T_current, q, g_intensity, term.intensity_jacobian);

  const bool smooth = ref.depth_smooth[i00] && ref.depth_smooth[i10] && ref.depth_smooth[i01] &&
                      ref.depth_smooth[i11];
  if (smooth) {
    term.has_depth = true;
    term.depth_residual = sample(ref.depth) - p.z;
    const Vec3f g_depth = dx_dp * sample(ref.depth_du) + dy_dp * sample(ref.depth_dv) -
                          Vec3f{0.0f, 0.0f, 1.0f};
    PointGradientToPose(reference_T_current, q, g_depth, term.depth_jacobian);
    term.depth_sigma = noise.Sigma(p.z);
  }
  return term;
}

}  // namespace plx

// Driver: residuals and pose Jacobians for a set of tracking rays. Compiled by
// core/cpu/tracking_cpu.cc and cuda/tracking_cuda.cu.
#pragma once

#include "core/kernels/kernel_types.h"
#include "core/kernels/ray_tracking.h"
#include "core/kernels/tracking_terms.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const ComputeTrackingTermsArgs& args) {
  const GridView g = args.grid;
  const TrainingFrameView f = args.frame;
  const TrackingParams p = args.params;
  const int32_t* const pixels = args.pixels;
  TrackingRayTerm* const terms = args.terms;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
    TrackingRayTerm& out = terms[i];
    for (int n = 0; n < kTrackingResiduals; ++n) out.weight[n] = 0.0f;
    const int32_t pixel = pixels[i];
    const int u = pixel % f.camera.width, v = pixel / f.camera.width;
    const float z = f.depth[pixel];
    if (!(z > 0.0f) || z > p.max_depth) return;
    const Vec3f dc = PixelDirectionCamera(f.camera, float(u), float(v));
    const float range_per_z = Norm(dc);
    const RayPoseJacobian<float> jac =
        RenderRayPoseJacobian(g, f.camera.world_T_camera, dc * (1.0f / range_per_z), p.render);
    if (jac.opacity < p.min_opacity) return;  // the map has no surface here to align with
    const float* target = f.color + 3 * pixel;
    for (int c = 0; c < 3; ++c) {
      out.residual[c] = jac.color[c] - target[c];
      for (int k = 0; k < kPoseDim; ++k) out.jacobian[c][k] = jac.d_color[c][k];
    }
    // The range normalised by opacity, so a ray that is not quite opaque does not read short:
    // d(D/O) = (dD - (D/O) dO) / O.
    const float range = jac.depth / jac.opacity;
    out.residual[3] = range - z * range_per_z;
    for (int k = 0; k < kPoseDim; ++k) {
      out.jacobian[3][k] = (jac.d_depth[k] - range * jac.d_opacity[k]) / jac.opacity;
    }
    if (p.l1_paper_weights) {
      // L = 0.5 mean over rays and channels |dC| + 1.0 mean over rays |dD| (reference tracker).
      const float color_weight = p.use_color ? 0.5f / 3.0f : 0.0f;
      for (int c = 0; c < 3; ++c) out.weight[c] = color_weight;
      out.weight[3] = p.use_depth ? 1.0f : 0.0f;
      return;
    }
    const float color_weight = p.use_color ? 1.0f / p.color_sigma : 0.0f;
    for (int c = 0; c < 3; ++c) out.weight[c] = color_weight;
    float sigma = p.depth_noise.Sigma(z);
    sigma = sigma > p.depth_sigma_floor ? sigma : p.depth_sigma_floor;
    // A ray whose weight spreads over several surfaces (a silhouette) has a rendered depth that
    // jumps as the pose moves; its spread joins the noise so it cannot dominate the step.
    out.weight[3] = p.use_depth ? 1.0f / sqrtf(sigma * sigma + jac.depth_variance) : 0.0f;
  });
}

}  // namespace plx::PLX_BACKEND_NS

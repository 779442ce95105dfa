// Per-ray pose Jacobian of the rendered colour and expected range (DESIGN.md §8, paper
// eq. 11-13 and Appendix A). Sample distances t_k = k * step are fixed relative to the camera,
// so a pose change moves every sample point p_k = o + t_k d rigidly with the camera:
//   d out / d xi = sum_k [ d out / d sigma_k  grad sigma(p_k)
//                          + w_k grad c(p_k) ] dp_k / dxi  +  w_k dc/dd dd/dxi   (colour only)
// where d out / d sigma_k comes from the compositing backward (volume_render.h), grad is the
// closed-form spatial gradient of the trilinear fields, and the last term is the change of the
// SH colour with the viewing direction.
#pragma once

#include "core/common/host_device.h"
#include "core/grid/grid_sample.h"
#include "core/grid/ray_march.h"
#include "core/grid/render_options.h"
#include "core/kernels/ray_render.h"
#include "core/math/pose_jacobian.h"
#include "core/math/rigid_transform.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/trilinear.h"
#include "core/math/volume_render.h"

namespace plx {

template <typename T>
struct RayPoseJacobian {
  T color[3];       // rendered colour, background included
  T depth;          // expected range sum_i w_i t_i
  T opacity;
  T depth_variance; // of the sample distances under the weights w_i / opacity
  T d_color[3][6];  // d color[c] / d xi
  T d_depth[6];     // d depth / d xi
  T d_opacity[6];   // d opacity / d xi
  int samples;
};

// `d_camera` is the unit ray direction in the camera frame.
template <typename T>
PLX_HD RayPoseJacobian<T> RenderRayPoseJacobian(const GridViewT<T>& grid,
                                                const RigidTransform<T>& world_T_camera,
                                                const Vec3<T>& d_camera,
                                                const RenderOptionsT<T>& opt) {
  const Vec3<T> origin = world_T_camera.translation();
  const Vec3<T> dir = world_T_camera.Rotate(d_camera);
  const RayRenderResult<T> fwd = RenderRay(grid, origin, dir, opt);
  RayPoseJacobian<T> out;
  for (int c = 0; c < 3; ++c) out.color[c] = fwd.color[c];
  out.depth = fwd.depth;
  out.opacity = fwd.opacity;
  if (fwd.opacity > T(0)) {
    const T mean = fwd.depth / fwd.opacity;
    const T var = fwd.depth_sq / fwd.opacity - mean * mean;
    out.depth_variance = var > T(0) ? var : T(0);
  } else {
    out.depth_variance = T(0);
  }
  out.samples = fwd.samples;
  for (int n = 0; n < 6; ++n) {
    out.d_color[0][n] = out.d_color[1][n] = out.d_color[2][n] = T(0);
    out.d_depth[n] = out.d_opacity[n] = T(0);
  }
  if (fwd.samples == 0) return out;

  T basis[kShBasisCount];
  EvalShBasis(dir, basis);
  T basis_grad[kShBasisCount][3];
  EvalShBasisGradient(dir, basis_grad);
  const T step = opt.step_voxels * grid.voxel_size;
  const T inv_voxel = T(1) / grid.voxel_size;
  // Composited quantities: r, g, b, range t and opacity (value 1 per sample).
  const T rendered[5] = {fwd.color[0], fwd.color[1], fwd.color[2], fwd.depth, fwd.opacity};
  CompositeBackwardState<T, 5> state = StartCompositeBackward<T, 5>(rendered);

  MarchRay(grid, origin, dir, opt.near, opt.far, step, [&](T t, const CellSample<T>& s) {
    T corner_density[8];
    GatherCornerDensity(grid, s, corner_density);
    const T sigma = Trilerp(corner_density, s.weights);
    if (sigma <= opt.sigma_threshold) return true;
    // Corner colours along this ray (before activation) and the interpolated SH.
    T corner_color[3][8];
    T sh[kShCoeffCount];
    for (int j = 0; j < kShCoeffCount; ++j) sh[j] = T(0);
    for (int k = 0; k < 8; ++k) {
      if (s.slots[k] < 0) {
        corner_color[0][k] = corner_color[1][k] = corner_color[2][k] = T(0);
        continue;
      }
      const T* src = grid.Sh(s.slots[k]);
      for (int c = 0; c < 3; ++c) {
        T v = T(0);
        for (int b = 0; b < kShBasisCount; ++b) v += src[c * kShBasisCount + b] * basis[b];
        corner_color[c][k] = v;
      }
      for (int j = 0; j < kShCoeffCount; ++j) sh[j] += s.weights[k] * src[j];
    }
    T color[3];
    bool unclamped[3];
    for (int c = 0; c < 3; ++c) {
      color[c] = ActivateColor(Trilerp(corner_color[c], s.weights), &unclamped[c]);
    }

    const T values[5] = {color[0], color[1], color[2], t, T(1)};
    T dsigma[5];
    const T w = CompositeBackwardStep<T, 5>(sigma, step, values, &state, dsigma);

    const Vec3<T> grad_sigma = TrilinearGradient(corner_density, s.frac) * inv_voxel;
    const Vec3<T> q = d_camera * t;  // the sample in the camera frame
    T row[6];
    for (int c = 0; c < 3; ++c) {
      Vec3<T> g = grad_sigma * dsigma[c];
      if (unclamped[c]) g += TrilinearGradient(corner_color[c], s.frac) * (w * inv_voxel);
      PointGradientToPose(world_T_camera, q, g, row);
      for (int n = 0; n < 6; ++n) out.d_color[c][n] += row[n];
      if (unclamped[c]) {
        Vec3<T> g_dir{T(0), T(0), T(0)};
        for (int b = 0; b < kShBasisCount; ++b) {
          const T coeff = sh[c * kShBasisCount + b] * w;
          g_dir += Vec3<T>{basis_grad[b][0], basis_grad[b][1], basis_grad[b][2]} * coeff;
        }
        DirectionGradientToPose(world_T_camera, d_camera, g_dir, row);
        for (int n = 3; n < 6; ++n) out.d_color[c][n] += row[n];
      }
    }
    PointGradientToPose(world_T_camera, q, grad_sigma * dsigma[3], row);
    for (int n = 0; n < 6; ++n) out.d_depth[n] += row[n];
    PointGradientToPose(world_T_camera, q, grad_sigma * dsigma[4], row);
    for (int n = 0; n < 6; ++n) out.d_opacity[n] += row[n];
    return state.transmittance >= opt.stop_transmittance;
  });
  return out;
}

}  // namespace plx

// Per-ray volume rendering through the brick grid: colour, expected range and opacity
// (DESIGN.md §6). Shared by the CPU and CUDA drivers.
#pragma once

#include "core/common/host_device.h"
#include "core/grid/grid_sample.h"
#include "core/grid/ray_march.h"
#include "core/grid/render_options.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/volume_render.h"

namespace plx {

template <typename T>
struct RayRenderResult {
  T color[3];    // composited colour including background
  T depth;       // sum_i w_i t_i: expected range, not normalised by opacity
  T opacity;     // sum_i w_i = 1 - final transmittance
  // Range at which the transmittance falls to 1/2 (0 when it never does): the surface a depth
  // sensor would report. Unlike the expected range it does not blend the two sides of a
  // silhouette, so depth images and depth metrics use it.
  T median_depth;
  T depth_sq;    // sum_i w_i t_i^2, for the spread of depth along the ray
  int samples;   // samples that contributed (density above threshold)
};

// Interpolated, activated colour of one sample seen along a ray with SH basis `basis`.
template <typename T>
PLX_HD void SampleColor(const GridViewT<T>& grid, const CellSample<T>& s,
                        const T basis[kShBasisCount], T color[3], bool unclamped[3]) {
  T sh[kShCoeffCount];
  SampleSh(grid, s, sh);
  T raw[3];
  ShToRawColor(sh, basis, raw);
  for (int c = 0; c < 3; ++c) color[c] = ActivateColor(raw[c], &unclamped[c]);
}

template <typename T>
PLX_HD RayRenderResult<T> RenderRay(const GridViewT<T>& grid, const Vec3<T>& origin,
                                    const Vec3<T>& dir, const RenderOptionsT<T>& opt) {
  T basis[kShBasisCount];
  EvalShBasis(dir, basis);
  const T step = opt.step_voxels * grid.voxel_size;
  RayRenderResult<T> out = {{T(0), T(0), T(0)}, T(0), T(0), T(0), T(0), 0};
  T transmittance = T(1);
  MarchRay(grid, origin, dir, opt.near, opt.far, step, [&](T t, const CellSample<T>& s) {
    const T sigma = SampleDensity(grid, s);
    if (sigma <= opt.sigma_threshold) return true;
    T color[3];
    bool unclamped[3];
    SampleColor(grid, s, basis, color, unclamped);
    const T before = transmittance;
    const T w = CompositeForwardStep(sigma, step, &transmittance);
    if (before >= T(0.5) && transmittance < T(0.5)) {
      // The sample stands for [t - step/2, t + step/2] at constant density.
      out.median_depth = t - T(0.5) * step + log(before / T(0.5)) / sigma;
    }
    for (int c = 0; c < 3; ++c) out.color[c] += w * color[c];
    out.depth += w * t;
    out.depth_sq += w * t * t;
    ++out.samples;
    return transmittance >= opt.stop_transmittance;
  });
  for (int c = 0; c < 3; ++c) out.color[c] += transmittance * opt.background[c];
  out.opacity = T(1) - transmittance;
  return out;
}

}  // namespace plx

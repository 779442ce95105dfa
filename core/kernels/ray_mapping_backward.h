// Per-ray backward of the mapping loss (DESIGN.md §7): given the forward result and the loss
// gradients w.r.t. the rendered colour and depth, walks the same samples again and scatters
// d loss / d density and d loss / d SH into the grid's gradient buffers.
#pragma once

#include "core/common/host_device.h"
#include "core/grid/grid_sample.h"
#include "core/grid/ray_march.h"
#include "core/grid/render_options.h"
#include "core/kernels/ray_render.h"
#include "core/math/volume_render.h"

namespace plx {

// `sh_min_weight`: samples whose weight is below it get no SH gradient (their colour barely
// shows in the pixel); 0 makes the backward exact.
template <typename T>
PLX_HD void MappingRayBackward(const GridViewT<T>& grid, GridGradViewT<T> grad,
                               const Vec3<T>& origin, const Vec3<T>& dir,
                               const RenderOptionsT<T>& opt, const RayRenderResult<T>& forward,
                               const T dL_dcolor[3], T dL_ddepth, T sh_min_weight) {
  T basis[kShBasisCount];
  EvalShBasis(dir, basis);
  const T step = opt.step_voxels * grid.voxel_size;
  // One composited scalar: g . colour + g_D depth, whose rendered value is g . C + g_D D.
  const T rendered = dL_dcolor[0] * forward.color[0] + dL_dcolor[1] * forward.color[1] +
                     dL_dcolor[2] * forward.color[2] + dL_ddepth * forward.depth;
  CompositeBackwardState<T, 1> state = StartCompositeBackward<T, 1>(&rendered);
  MarchRay(grid, origin, dir, opt.near, opt.far, step, [&](T t, const CellSample<T>& s) {
    const T sigma = SampleDensity(grid, s);
    if (sigma <= opt.sigma_threshold) return true;
    T color[3];
    bool unclamped[3];
    SampleColor(grid, s, basis, color, unclamped);
    const T value = dL_dcolor[0] * color[0] + dL_dcolor[1] * color[1] +
                    dL_dcolor[2] * color[2] + dL_ddepth * t;
    T dL_dsigma;
    const T w = CompositeBackwardStep<T, 1>(sigma, step, &value, &state, &dL_dsigma);
    T dL_draw[3];
    for (int c = 0; c < 3; ++c) dL_draw[c] = unclamped[c] ? w * dL_dcolor[c] : T(0);
    ScatterSampleGrad(s, dL_dsigma, w > sh_min_weight ? dL_draw : nullptr, basis, grad);
    return state.transmittance >= opt.stop_transmittance;
  });
}

}  // namespace plx

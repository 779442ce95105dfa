// Driver: RMSProp on the vertices that received gradient (DESIGN.md §7). Compiled by
// core/cpu/optimizer_cpu.cc and cuda/optimizer_cuda.cu.
#pragma once

#include <cmath>

#include "core/kernels/kernel_types.h"

namespace plx {

// One RMSProp update of a single parameter; the first update seeds the average with g^2.
PLX_HD float RmsPropUpdate(float* value, float* rms, float g, float lr, float beta, float eps) {
  const float avg = *rms == 0.0f ? g * g : beta * *rms + (1.0f - beta) * g * g;
  *rms = avg;
  *value -= lr * g / (sqrtf(avg) + eps);
  return avg;
}

}  // namespace plx

namespace plx::PLX_BACKEND_NS {

void RmsPropStep(const ExecContext& ctx, const GridView& grid, const GridGradView& grad,
                 const OptimizerStateView& state, const RmsPropParams& params) {
  const GridView g = grid;
  const GridGradView gg = grad;
  const OptimizerStateView s = state;
  const RmsPropParams p = params;
  ParallelFor(ctx, g.num_vertices(), [=] PLX_HD_LAMBDA(int64_t i) {
    if (gg.touched[i] == 0) return;
    gg.touched[i] = 0;
    const float before = g.density[i];
    RmsPropUpdate(g.density + i, s.rms_density + i, gg.density[i], p.lr_density, p.beta,
                  p.epsilon);
    gg.density[i] = 0.0f;
    if (before <= p.sigma_threshold && g.density[i] > p.sigma_threshold) {
      int v[3];
      g.VertexCoords(i, v);
      g.MarkCellsAroundVertex(v[0], v[1], v[2]);
    }
    float* sh = g.sh + i * kShCoeffCount;
    float* sh_grad = gg.sh + i * kShCoeffCount;
    float* sh_rms = s.rms_sh + i * kShCoeffCount;
    for (int j = 0; j < kShCoeffCount; ++j) {
      if (sh_grad[j] == 0.0f) continue;  // e.g. a clamped colour channel
      RmsPropUpdate(sh + j, sh_rms + j, sh_grad[j], p.lr_sh, p.beta, p.epsilon);
      sh_grad[j] = 0.0f;
    }
  });
}

}  // namespace plx::PLX_BACKEND_NS

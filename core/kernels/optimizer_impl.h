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

// Updates the density and SH of one touched vertex and clears its gradients.
PLX_HD void UpdateVertex(const GridView& g, const GridWriteView& w, const GridGradView& gg,
                         const OptimizerStateView& s, const RmsPropParams& p, int64_t i) {
  float& density = w.Density(i);
  const float before = density;
  RmsPropUpdate(&density, s.rms_density + i, gg.density[i], p.lr_density, p.beta, p.epsilon);
  gg.density[i] = 0.0f;
  if (before <= p.sigma_threshold && density > p.sigma_threshold) {
    int v[3];
    g.VertexCoords(i, v);
    w.MarkCellsAroundVertex(g, v[0], v[1], v[2]);
  }
  float* sh = w.Sh(i);
  float* sh_grad = gg.sh + i * kShCoeffCount;
  float* sh_rms = s.rms_sh + i * kShCoeffCount;
  // Branch-free so the compiler vectorises it: a coefficient without gradient (a clamped colour
  // channel, or a sample too faint for SH gradients) keeps its value and its running average.
  for (int j = 0; j < kShCoeffCount; ++j) {
    const float g = sh_grad[j], rms = sh_rms[j];
    const float seeded = rms == 0.0f ? g * g : p.beta * rms + (1.0f - p.beta) * g * g;
    const float avg = g == 0.0f ? rms : seeded;
    sh_rms[j] = avg;
    sh[j] -= g == 0.0f ? 0.0f : p.lr_sh * g / (sqrtf(avg) + p.epsilon);
    sh_grad[j] = 0.0f;
  }
}

}  // namespace plx

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const RmsPropStepArgs& args) {
  const GridView g = args.grid;
  const GridWriteView w = args.write;
  const GridGradView gg = args.grad;
  const OptimizerStateView s = args.state;
  const RmsPropParams p = args.params;
  // brick_slices work items per brick, each a contiguous run of its vertices: most bricks
  // receive no gradient in a batch and are skipped whole. The bricks' touched flags are cleared
  // in a second pass, once every slice has read them.
  const int slices =
      p.brick_slices > 0 && kBrickVertices % p.brick_slices == 0 ? p.brick_slices : 1;
  const int64_t per_slice = kBrickVertices / slices;
  ParallelFor(ctx, g.num_bricks * slices, [=] PLX_HD_LAMBDA(int64_t item) {
    const int64_t brick = item / slices;
    if (gg.brick_touched[brick] == 0) return;
    const int64_t first = brick * kBrickVertices + (item % slices) * per_slice;
    for (int64_t i = first; i < first + per_slice; ++i) {
      if (gg.touched[i] == 0) continue;
      gg.touched[i] = 0;
      UpdateVertex(g, w, gg, s, p, i);
    }
  });
  ParallelFor(ctx, g.num_bricks, [=] PLX_HD_LAMBDA(int64_t brick) { gg.brick_touched[brick] = 0; });
}

}  // namespace plx::PLX_BACKEND_NS

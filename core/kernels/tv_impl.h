// Driver: total-variation regulariser gradients (Plenoxels' TV, DESIGN.md §7) on a run of
// stored vertices, added to the gradient buffers before the optimiser step. Compiled by
// core/cpu/tv_cpu.cc and cuda/tv_cuda.cu.
#pragma once

#include "core/common/atomics.h"
#include "core/kernels/kernel_types.h"
#include "core/math/total_variation.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const AddTvGradientArgs& args) {
  const GridView g = args.grid;
  const GridGradView gg = args.grad;
  const int64_t total = g.num_vertices();
  const int64_t first_vertex = args.first_vertex;
  const float lambda_density = args.lambda_density;
  const float lambda_sh = args.lambda_sh;
  ParallelFor(ctx, args.vertex_count, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t vertex = (first_vertex + i) % total;
    int v[3];
    g.VertexCoords(vertex, v);
    int64_t slots[4] = {vertex, g.VertexSlot(v[0] + 1, v[1], v[2]),
                        g.VertexSlot(v[0], v[1] + 1, v[2]), g.VertexSlot(v[0], v[1], v[2] + 1)};
    float values[4], grads[4];
    if (lambda_density > 0.0f) {
      // Unstored neighbours read as empty space (zero density).
      for (int k = 0; k < 4; ++k) values[k] = slots[k] >= 0 ? g.Density(slots[k]) : 0.0f;
      TvGradient(values, lambda_density, grads);
      for (int k = 0; k < 4; ++k) {
        if (slots[k] < 0) continue;
        AtomicAdd(gg.density + slots[k], grads[k]);
        gg.MarkTouched(slots[k]);
      }
    }
    if (lambda_sh > 0.0f) {
      // Unstored neighbours take the centre's value: no colour edge at the map's border.
      for (int j = 0; j < kShCoeffCount; ++j) {
        for (int k = 0; k < 4; ++k) {
          values[k] = g.Sh(slots[k] >= 0 ? slots[k] : vertex)[j];
        }
        TvGradient(values, lambda_sh, grads);
        for (int k = 0; k < 4; ++k) {
          if (slots[k] >= 0) AtomicAdd(gg.sh + slots[k] * kShCoeffCount + j, grads[k]);
        }
      }
      for (int k = 0; k < 4; ++k) {
        if (slots[k] >= 0) gg.MarkTouched(slots[k]);
      }
    }
  });
}

}  // namespace plx::PLX_BACKEND_NS

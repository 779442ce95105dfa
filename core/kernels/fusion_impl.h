// Driver: depth-guided initialisation of stored vertices (see depth_fusion.h). Compiled by
// core/cpu/fusion_cpu.cc and cuda/fusion_cuda.cu.
#pragma once

#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"

namespace plx::PLX_BACKEND_NS {

void FuseDepth(const ExecContext& ctx, const GridView& grid, const GridWriteView& write,
               int64_t first_vertex, int64_t vertex_count, const TrainingFrameView* frames,
               int num_frames, const FusionParams& params) {
  const GridView g = grid;
  const GridWriteView w = write;
  const FusionParams p = params;
  ParallelFor(ctx, vertex_count, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t vertex = first_vertex + i;
    int v[3];
    g.VertexCoords(vertex, v);
    const VertexFusion f = FuseVertex(g.VertexPosition(v[0], v[1], v[2]), frames, num_frames, p);
    w.Density(vertex) = f.density;
    float* sh = w.Sh(vertex);
    for (int j = 0; j < kShCoeffCount; ++j) sh[j] = 0.0f;
    for (int c = 0; c < 3; ++c) sh[c * kShBasisCount] = ShDcForColor(f.color[c]);
  });
}

}  // namespace plx::PLX_BACKEND_NS

// Driver: fill every stored vertex of one grid by trilinear sampling of another (coarse-to-fine
// upsampling). Compiled by core/cpu/resample_cpu.cc and cuda/resample_cuda.cu.
#pragma once

#include "core/grid/grid_sample.h"
#include "core/kernels/kernel_types.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const ResampleGridArgs& args) {
  const GridView dst = args.target;
  const GridWriteView out = args.target_write;
  const GridView src = args.source;
  ParallelFor(ctx, dst.num_vertices(), [=] PLX_HD_LAMBDA(int64_t vertex) {
    int v[3];
    dst.VertexCoords(vertex, v);
    const Vec3f q = src.ToGrid(dst.VertexPosition(v[0], v[1], v[2]));
    float* sh = out.Sh(vertex);
    bool inside = true;
    for (int a = 0; a < 3; ++a) inside = inside && q[a] >= 0.0f && q[a] <= src.vertex_extent(a) - 1;
    if (!inside) {
      out.Density(vertex) = 0.0f;
      for (int j = 0; j < kShCoeffCount; ++j) sh[j] = 0.0f;
      return;
    }
    CellSample<float> s;
    LocateCell(src, q, &s);
    out.Density(vertex) = SampleDensity(src, s);
    SampleSh(src, s, sh);
  });
}

}  // namespace plx::PLX_BACKEND_NS

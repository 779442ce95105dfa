// Driver: depth-guided initialisation of stored vertices (see depth_fusion.h). Compiled by
// core/cpu/fusion_cpu.cc and cuda/fusion_cuda.cu.
#pragma once

#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const FuseDepthArgs& args) {
  const GridView g = args.grid;
  const GridWriteView w = args.write;
  const FusionParams p = args.params;
  const int64_t first_vertex = args.first_vertex;
  const TrainingFrameView* const frames = args.frames;
  const int num_frames = args.num_frames;
  ParallelFor(ctx, args.vertex_count, [=] PLX_HD_LAMBDA(int64_t i) {
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

void Run(const ExecContext& ctx, const ObserveSurfaceArgs& args) {
  const GridView g = args.grid;
  const IsoBrickList bricks = args.bricks;
  const FusionParams p = args.params;
  const TrainingFrameView* const frames = args.frames;
  const int num_frames = args.num_frames;
  float* const value = args.value;
  ParallelFor(ctx, bricks.count * kBrickVertices, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t vertex = IsoWorkVertex(g, bricks, i);
    if (vertex < 0) return;
    int v[3];
    g.VertexCoords(vertex, v);
    const ProjectiveTsdf t =
        AverageProjectiveTsdf<false>(g.VertexPosition(v[0], v[1], v[2]), frames, num_frames, p);
    value[vertex] = t.weight > 0.0f ? -t.tsdf : kIsoNoValue;
  });
}

}  // namespace plx::PLX_BACKEND_NS

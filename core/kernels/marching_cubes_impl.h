// Drivers: marching cubes on the grid's density (per-cell and per-vertex work of
// core/kernels/marching_cubes.h). Compiled by core/cpu/marching_cubes_cpu.cc and
// cuda/marching_cubes_cuda.cu.
#pragma once

#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"

namespace plx::PLX_BACKEND_NS {

void CountIsoTriangles(const ExecContext& ctx, const GridView& grid, int64_t first_vertex,
                       int64_t count, const IsoSurfaceParams& params, uint8_t* triangles) {
  const GridView g = grid;
  const IsoSurfaceParams p = params;
  ParallelFor(ctx, count, [=] PLX_HD_LAMBDA(int64_t i) {
    int cell[3];
    const int mask = IsoCellCase(g, first_vertex + i, p.iso_level, cell);
    triangles[i] = mask < 0 ? 0 : p.table->triangle_count[mask];
  });
}

void EmitIsoTriangles(const ExecContext& ctx, const GridView& grid, int64_t first_vertex,
                      int64_t count, const IsoSurfaceParams& params,
                      const int64_t* first_triangle, int64_t* edge_keys) {
  const GridView g = grid;
  const IsoSurfaceParams p = params;
  ParallelFor(ctx, count, [=] PLX_HD_LAMBDA(int64_t i) {
    int cell[3];
    const int mask = IsoCellCase(g, first_vertex + i, p.iso_level, cell);
    if (mask <= 0) return;
    const int n = p.table->triangle_count[mask];
    if (n == 0) return;
    int64_t* out = edge_keys + 3 * first_triangle[i];
    for (int j = 0; j < 3 * n; ++j) out[j] = IsoCellEdgeKey(g, cell, p.table->edges[mask][j]);
  });
}

void ComputeIsoVertices(const ExecContext& ctx, const GridView& grid, const int64_t* edge_keys,
                        int64_t count, const IsoSurfaceParams& params, float* positions,
                        float* normals, uint8_t* colors, uint8_t* observed) {
  const GridView g = grid;
  const IsoSurfaceParams p = params;
  ParallelFor(ctx, count, [=] PLX_HD_LAMBDA(int64_t i) {
    const IsoVertex v = ComputeIsoVertex(g, edge_keys[i], p);
    positions[3 * i + 0] = v.position.x;
    positions[3 * i + 1] = v.position.y;
    positions[3 * i + 2] = v.position.z;
    normals[3 * i + 0] = v.normal.x;
    normals[3 * i + 1] = v.normal.y;
    normals[3 * i + 2] = v.normal.z;
    for (int c = 0; c < 3; ++c) colors[3 * i + c] = v.color[c];
    observed[i] = v.observed ? 1 : 0;
  });
}

}  // namespace plx::PLX_BACKEND_NS

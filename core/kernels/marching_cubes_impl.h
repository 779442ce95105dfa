// Drivers: marching cubes on the grid's density (per-cell and per-vertex work of
// core/kernels/marching_cubes.h). Compiled by core/cpu/marching_cubes_cpu.cc and
// cuda/marching_cubes_cuda.cu.
#pragma once

#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const CountIsoTrianglesArgs& args) {
  const GridView g = args.grid;
  const IsoSurfaceParams p = args.params;
  const IsoBrickList bricks = args.bricks;
  const int64_t first_vertex = args.first_vertex;
  uint8_t* const triangles = args.triangles;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
    int cell[3];
    const int mask = IsoCellCase(g, IsoWorkVertex(g, bricks, first_vertex + i), p, cell);
    triangles[i] = mask < 0 ? 0 : p.table->triangle_count[mask];
  });
}

void Run(const ExecContext& ctx, const EmitIsoTrianglesArgs& args) {
  const GridView g = args.grid;
  const IsoSurfaceParams p = args.params;
  const IsoBrickList bricks = args.bricks;
  const int64_t first_vertex = args.first_vertex;
  const int64_t* const first_triangle = args.first_triangle;
  int64_t* const edge_keys = args.edge_keys;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
    int cell[3];
    const int mask = IsoCellCase(g, IsoWorkVertex(g, bricks, first_vertex + i), p, cell);
    if (mask <= 0) return;
    const int n = p.table->triangle_count[mask];
    if (n == 0) return;
    int64_t* out = edge_keys + 3 * first_triangle[i];
    for (int j = 0; j < 3 * n; ++j) out[j] = IsoCellEdgeKey(g, cell, p.table->edges[mask][j]);
  });
}

void Run(const ExecContext& ctx, const ComputeIsoVerticesArgs& args) {
  const GridView g = args.grid;
  const IsoSurfaceParams p = args.params;
  const int64_t* const edge_keys = args.edge_keys;
  float* const positions = args.positions;
  float* const normals = args.normals;
  uint8_t* const colors = args.colors;
  uint8_t* const observed = args.observed;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
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

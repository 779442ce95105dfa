// Driver: recompute exact cell occupancy for every active block. Compiled by
// core/cpu/occupancy_cpu.cc and cuda/occupancy_cuda.cu.
#pragma once

#include "core/grid/occupancy.h"
#include "core/kernels/kernel_types.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const RefreshOccupancyArgs& args) {
  const GridView g = args.grid;
  uint64_t* const cell_bits = args.write.cell_bits;
  const int64_t* const active_blocks = args.active_blocks;
  const float threshold = args.threshold;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t block = active_blocks[i];
    uint64_t bits[kBrickEdge];
    ComputeBlockOccupancy(g, block, threshold, bits);
    uint64_t* out = cell_bits + g.block_cells[block];
    for (int z = 0; z < kBrickEdge; ++z) out[z] = bits[z];
  });
}

}  // namespace plx::PLX_BACKEND_NS

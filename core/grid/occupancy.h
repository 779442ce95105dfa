// Exact cell occupancy of one index block (see GridViewT::cell_bits): a cell is occupied when
// any of its 8 corners is stored with density above the threshold.
#pragma once

#include <cstdint>

#include "core/common/host_device.h"
#include "core/grid/grid_view.h"

namespace plx {

template <typename T>
PLX_HD void ComputeBlockOccupancy(const GridViewT<T>& grid, int64_t block_linear, T threshold,
                                  uint64_t bits[kBrickEdge]) {
  const int bx = static_cast<int>(block_linear % grid.dims[0]);
  const int by = static_cast<int>((block_linear / grid.dims[0]) % grid.dims[1]);
  const int bz = static_cast<int>(block_linear / (int64_t{grid.dims[0]} * grid.dims[1]));
  // Vertices 8b .. 8b+8 along each axis: bit x of row[z][y] says vertex (x, y, z) is positive.
  constexpr int kSpan = kBrickEdge + 1;
  uint16_t row[kSpan][kSpan];
  for (int z = 0; z < kSpan; ++z) {
    for (int y = 0; y < kSpan; ++y) {
      uint16_t r = 0;
      for (int x = 0; x < kSpan; ++x) {
        const int64_t slot = grid.VertexSlot(bx * kBrickEdge + x, by * kBrickEdge + y,
                                             bz * kBrickEdge + z);
        if (slot >= 0 && grid.Density(slot) > threshold) r |= static_cast<uint16_t>(1u << x);
      }
      row[z][y] = r;
    }
  }
  for (int z = 0; z < kBrickEdge; ++z) {
    uint64_t word = 0;
    for (int y = 0; y < kBrickEdge; ++y) {
      const unsigned m = row[z][y] | row[z][y + 1] | row[z + 1][y] | row[z + 1][y + 1];
      const uint64_t cells = (m | (m >> 1)) & 0xFFu;  // cell x touches vertices x and x + 1
      word |= cells << (y * kBrickEdge);
    }
    bits[z] = word;
  }
}

}  // namespace plx

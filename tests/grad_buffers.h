// Gradient buffers with the grid's slot layout, for tests that call backend kernels directly.
#pragma once

#include <cstdint>

#include "core/common/unified_allocator.h"
#include "core/grid/grid_view.h"
#include "core/grid/sparse_grid.h"

namespace plx::testing {

struct GradBuffers {
  UnifiedVector<float> density, sh;
  UnifiedVector<uint8_t> touched, brick_touched;

  explicit GradBuffers(const SparseGrid& grid)
      : density(grid.num_vertices(), 0.0f),
        sh(grid.num_vertices() * kShCoeffCount, 0.0f),
        touched(grid.num_vertices(), 0),
        brick_touched(grid.num_bricks(), 0) {}
  GridGradView view() {
    return GridGradView{density.data(), sh.data(), touched.data(), brick_touched.data()};
  }
};

}  // namespace plx::testing

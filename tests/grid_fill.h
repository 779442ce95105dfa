// Host-side writes of every vertex of a grid, for tests that set up parameters by hand (the
// grid stores bricks apart, see SparseGrid; these go brick by brick, in vertex order).
#pragma once

#include <cstdint>

#include "core/grid/sparse_grid.h"

namespace plx::testing {

// density[v] = next() for every vertex v in slot order.
template <typename Next>
void FillDensity(SparseGrid& grid, Next next) {
  for (int64_t slot = 0; slot < grid.num_bricks(); ++slot) {
    float* d = grid.mutable_brick_density(slot);
    for (int i = 0; i < kBrickVertices; ++i) d[i] = next();
  }
}

// Every SH coefficient, vertex by vertex, 27 per vertex.
template <typename Next>
void FillSh(SparseGrid& grid, Next next) {
  for (int64_t slot = 0; slot < grid.num_bricks(); ++slot) {
    float* s = grid.mutable_brick_sh(slot);
    for (int64_t i = 0; i < int64_t{kBrickVertices} * kShCoeffCount; ++i) s[i] = next();
  }
}

}  // namespace plx::testing

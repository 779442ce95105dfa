// Keeping a map's cell occupancy in step with its densities. It needs both the grid's host-side
// list of active blocks (core/grid/sparse_grid.h) and a backend to recompute the bits, so it
// lives here, above both, rather than in either.
#pragma once

#include "core/grid/sparse_grid.h"
#include "core/kernels/backend.h"

namespace plx {

// Makes the map's cell occupancy exact for its current densities when it is stale.
absl::Status RefreshOccupancyIfStale(Backend& backend, SparseGrid& grid, float sigma_threshold);

}  // namespace plx

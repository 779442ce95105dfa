// Keeping a map's cell occupancy in step with its densities. It needs both the grid's host-side
// list of active blocks (core/grid/sparse_grid.h) and a backend to recompute the bits, so it
// lives here, above both, rather than in either.
#pragma once

#include "core/grid/plenoxel_map.h"
#include "core/grid/sparse_grid.h"
#include "core/kernels/backend.h"

namespace plx {

// Makes the map's cell occupancy exact for its current densities when it is stale.
absl::Status RefreshOccupancyIfStale(Backend& backend, SparseGrid& grid, float sigma_threshold);

// The same for a map at its own threshold: what a map needs before it is handed to readers
// (a loaded map's occupancy is conservative, every cell of an active block set, which renders
// correctly but marches up to ~7x more samples per ray).
inline absl::Status RefreshOccupancyIfStale(Backend& backend, PlenoxelMap& map) {
  return RefreshOccupancyIfStale(backend, map.grid, map.render.sigma_threshold);
}

}  // namespace plx

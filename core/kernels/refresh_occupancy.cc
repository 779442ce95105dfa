#include "core/kernels/refresh_occupancy.h"

namespace plx {

void RefreshOccupancyIfStale(Backend& backend, SparseGrid& grid, float sigma_threshold) {
  if (!grid.occupancy_stale()) return;
  const UnifiedVector<int64_t>& blocks = grid.active_blocks();
  if (!blocks.empty()) {
    backend.RefreshOccupancy(grid.view(), blocks.data(), static_cast<int64_t>(blocks.size()),
                             sigma_threshold);
  }
  grid.set_occupancy_fresh();
}

}  // namespace plx

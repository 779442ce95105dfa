#include "core/kernels/refresh_occupancy.h"

namespace plx {

absl::Status RefreshOccupancyIfStale(Backend& backend, SparseGrid& grid, float sigma_threshold) {
  if (!grid.occupancy_stale()) return absl::OkStatus();
  const UnifiedVector<int64_t>& blocks = grid.active_blocks();
  if (!blocks.empty()) {
    absl::Status refreshed =
        backend.RefreshOccupancy(grid.view(), grid.write_view(), blocks.data(),
                                 static_cast<int64_t>(blocks.size()), sigma_threshold);
    if (!refreshed.ok()) return refreshed;
  }
  grid.set_occupancy_fresh();
  return absl::OkStatus();
}

}  // namespace plx

// A map as a mapping job publishes it, for the MapStore tests (store, leases, snapshots,
// handoffs): `bricks` bricks in a row at `voxel_size`, occupancy refreshed unless `refresh` is
// false (a version a reader would still have to refresh).
#pragma once

#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/refresh_occupancy.h"

namespace plx::testing {

inline std::shared_ptr<const PlenoxelMap> MapWithBricks(float voxel_size, int bricks,
                                                        bool refresh = true) {
  auto map = std::make_shared<PlenoxelMap>(voxel_size);
  std::vector<BrickCoord> coords;
  for (int i = 0; i < bricks; ++i) coords.push_back({i, 0, 0});
  EXPECT_TRUE(map->grid.AllocateBricks(coords, 1.0f).ok());
  if (refresh) {
    EXPECT_TRUE(RefreshOccupancyIfStale(*MakeCpuBackend(1), *map).ok());
  }
  return map;
}

}  // namespace plx::testing

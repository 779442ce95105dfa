#include "core/grid/occupancy.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/grid/sparse_grid.h"
#include "core/kernels/backend.h"
#include "core/kernels/ray_render.h"
#include "core/kernels/refresh_occupancy.h"
#include "tests/grid_fill.h"

namespace plx {
namespace {

// A grid where most vertices are empty (density <= 0) and a few blobs are dense.
SparseGrid MakeSparseDensityGrid(std::mt19937& rng) {
  SparseGrid grid(0.05f);
  std::vector<BrickCoord> bricks;
  for (int x = -2; x <= 1; ++x)
    for (int y = -2; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z) bricks.push_back({x, y, z});
  EXPECT_TRUE(grid.AllocateBricks(bricks).ok());
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  testing::FillDensity(grid, [&] { return u(rng) < 0.05f ? 40.0f * u(rng) : -u(rng); });
  testing::FillSh(grid, [&] { return 0.2f * (u(rng) - 0.5f); });
  return grid;
}

TEST(OccupancyTest, RefreshedBitsMatchCornerDensities) {
  std::mt19937 rng(31);
  SparseGrid grid = MakeSparseDensityGrid(rng);
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  ASSERT_TRUE(grid.occupancy_stale());
  ASSERT_TRUE(RefreshOccupancyIfStale(*backend, grid, 0.0f).ok());
  EXPECT_FALSE(grid.occupancy_stale());
  const GridView g = grid.view();
  int occupied = 0, empty = 0;
  for (int64_t block : grid.active_blocks()) {
    const int bx = block % g.dims[0], by = (block / g.dims[0]) % g.dims[1],
              bz = block / (int64_t{g.dims[0]} * g.dims[1]);
    const int32_t bits = g.block_cells[block];
    for (int z = 0; z < 8; ++z)
      for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x) {
          bool expect = false;
          for (int c = 0; c < 8; ++c) {
            const int64_t slot = g.VertexSlot(bx * 8 + x + (c & 1), by * 8 + y + ((c >> 1) & 1),
                                              bz * 8 + z + ((c >> 2) & 1));
            expect |= slot >= 0 && g.Density(slot) > 0.0f;
          }
          EXPECT_EQ(g.CellOccupied(bits, x, y, z), expect);
          (expect ? occupied : empty)++;
        }
  }
  EXPECT_GT(occupied, 1000);
  EXPECT_GT(empty, 1000);
}

TEST(OccupancyTest, SkippingEmptyCellsDoesNotChangeRenders) {
  std::mt19937 rng(32);
  SparseGrid grid = MakeSparseDensityGrid(rng);
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  RenderOptions options;
  options.sigma_threshold = 0.0f;
  const GridView all_occupied = grid.view();  // fresh bricks: every cell marked occupied
  std::vector<RayRenderResult<float>> before;
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::vector<std::pair<Vec3f, Vec3f>> rays;
  for (int r = 0; r < 300; ++r) {
    const Vec3f o = Normalized(Vec3f{n(rng), n(rng), n(rng)}) * 1.5f;
    const Vec3f target{0.3f * n(rng), 0.3f * n(rng), 0.2f * n(rng)};
    rays.push_back({o, Normalized(target - o)});
    before.push_back(RenderRay(all_occupied, rays.back().first, rays.back().second, options));
  }
  ASSERT_TRUE(RefreshOccupancyIfStale(*backend, grid, options.sigma_threshold).ok());
  const GridView refreshed = grid.view();
  int hits = 0;
  for (size_t r = 0; r < rays.size(); ++r) {
    const RayRenderResult<float> after =
        RenderRay(refreshed, rays[r].first, rays[r].second, options);
    EXPECT_EQ(after.samples, before[r].samples);
    EXPECT_FLOAT_EQ(after.depth, before[r].depth);
    EXPECT_FLOAT_EQ(after.color[1], before[r].color[1]);
    hits += after.samples > 0;
  }
  EXPECT_GT(hits, 50);
}

TEST(OccupancyTest, MarkingAVertexOccupiesItsEightCells) {
  SparseGrid grid(0.1f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {1, 0, 0}}).ok());
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  testing::FillDensity(grid, [] { return 0.0f; });
  ASSERT_TRUE(RefreshOccupancyIfStale(*backend, grid, 0.0f).ok());
  GridView g = grid.view();
  // Vertex at local (0, 3, 3) of brick (1,0,0): its cells straddle blocks (0,..) and (1,..).
  const int ox = -grid.index_min()[0] * 8, oy = -grid.index_min()[1] * 8,
            oz = -grid.index_min()[2] * 8;
  const int vx = ox + 8, vy = oy + 3, vz = oz + 3;
  grid.write_view().MarkCellsAroundVertex(g, vx, vy, vz);
  for (int c = 0; c < 8; ++c) {
    const int cx = vx - (c & 1), cy = vy - ((c >> 1) & 1), cz = vz - ((c >> 2) & 1);
    EXPECT_TRUE(g.CellOccupied(g.BlockCells(cx >> 3, cy >> 3, cz >> 3), cx & 7, cy & 7, cz & 7));
  }
  EXPECT_FALSE(g.CellOccupied(g.BlockCells((vx + 1) >> 3, vy >> 3, vz >> 3), (vx + 1) & 7, vy & 7,
                              vz & 7));
}

}  // namespace
}  // namespace plx

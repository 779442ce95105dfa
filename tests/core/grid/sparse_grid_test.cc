#include "core/grid/sparse_grid.h"

#include <gtest/gtest.h>

namespace plx {
namespace {

TEST(SparseGridTest, AllocatesBricksOnceAndFindsThem) {
  SparseGrid grid(0.02f);
  std::vector<BrickCoord> bricks = {{0, 0, 0}, {1, 0, 0}, {-3, 2, 5}, {0, 0, 0}};
  auto added = grid.AllocateBricks(bricks, 0.5f);
  ASSERT_TRUE(added.ok()) << added.status();
  EXPECT_EQ(*added, 3);
  EXPECT_EQ(grid.num_bricks(), 3);
  EXPECT_EQ(grid.num_vertices(), 3 * 512);
  EXPECT_EQ(grid.FindBrick({1, 0, 0}), 1);
  EXPECT_EQ(grid.FindBrick({-3, 2, 5}), 2);
  EXPECT_EQ(grid.FindBrick({7, 7, 7}), -1);
  EXPECT_EQ(grid.DensityValues().size(), 3u * 512);
  EXPECT_FLOAT_EQ(grid.density(100), 0.5f);
  EXPECT_EQ(grid.ShValues().size(), 3u * 512 * 27);
  // Allocating again adds nothing.
  EXPECT_EQ(*grid.AllocateBricks(bricks), 0);
}

TEST(SparseGridTest, IndexGrowsAndKeepsSlots) {
  SparseGrid grid(0.05f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}}).ok());
  grid.mutable_brick_density(0)[7] = 3.0f;
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{40, -30, 12}}).ok());
  EXPECT_EQ(grid.FindBrick({0, 0, 0}), 0);
  EXPECT_EQ(grid.FindBrick({40, -30, 12}), 1);
  EXPECT_FLOAT_EQ(grid.density(7), 3.0f);
  const auto& lo = grid.index_min();
  const auto& dims = grid.index_dims();
  EXPECT_LE(lo[0], 0);
  EXPECT_GE(lo[0] + dims[0], 41);
  EXPECT_LE(lo[1], -30);
}

TEST(SparseGridTest, ViewMapsWorldVerticesToSlots) {
  SparseGrid grid(0.1f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{2, -1, 0}}).ok());
  GridView view = grid.view();
  // Vertex local (3, 4, 5) of brick (2, -1, 0) sits at world (19, -4, 5) * 0.1.
  const int local = 3 + 8 * 4 + 64 * 5;
  const auto p = grid.VertexPosition(0, local);
  EXPECT_NEAR(p[0], 1.9f, 1e-6);
  EXPECT_NEAR(p[1], -0.4f, 1e-6);
  EXPECT_NEAR(p[2], 0.5f, 1e-6);
  const Vec3f q = view.ToGrid(Vec3f{p[0], p[1], p[2]});
  const int64_t slot = view.VertexSlot(static_cast<int>(std::lround(q.x)),
                                       static_cast<int>(std::lround(q.y)),
                                       static_cast<int>(std::lround(q.z)));
  EXPECT_EQ(slot, local);
}

TEST(SparseGridTest, ASubsetSharesTheKeptBricksAndDropsTheOthers) {
  SparseGrid grid(0.05f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {1, 0, 0}, {5, -2, 3}},
                                  0.25f).ok());
  grid.mutable_brick_density(2)[9] = 4.0f;
  grid.mutable_brick_sh(2)[30] = -1.5f;
  SparseGrid source = grid.Publish();  // as a published version is: no longer written
  const std::vector<uint8_t> keep = {1, 0, 1};
  SparseGrid subset = source.ShareSubset(keep);
  ASSERT_EQ(subset.num_bricks(), 2);
  EXPECT_EQ(subset.FindBrick({0, 0, 0}), 0);
  EXPECT_EQ(subset.FindBrick({1, 0, 0}), -1);
  EXPECT_EQ(subset.FindBrick({5, -2, 3}), 1);
  EXPECT_EQ(subset.index_min(), source.index_min());
  EXPECT_EQ(subset.index_dims(), source.index_dims());
  EXPECT_TRUE(subset.occupancy_stale());
  // Shared, not copied: the same storage until the subset writes.
  EXPECT_EQ(subset.brick_density(1), source.brick_density(2));
  EXPECT_FLOAT_EQ(subset.brick_density(1)[9], 4.0f);
  EXPECT_FLOAT_EQ(subset.brick_sh(1)[30], -1.5f);
  subset.mutable_brick_density(1)[9] = 7.0f;  // clones first
  EXPECT_NE(subset.brick_density(1), source.brick_density(2));
  EXPECT_FLOAT_EQ(source.brick_density(2)[9], 4.0f);
  EXPECT_FLOAT_EQ(subset.brick_sh(1)[30], -1.5f);
  // Its view finds the kept brick's vertices where the source's does.
  const GridView view = subset.view();
  const auto p = subset.VertexPosition(1, 9);
  const Vec3f q = view.ToGrid(Vec3f{p[0], p[1], p[2]});
  EXPECT_EQ(view.VertexSlot(static_cast<int>(std::lround(q.x)),
                            static_cast<int>(std::lround(q.y)),
                            static_cast<int>(std::lround(q.z))),
            512 + 9);
}

TEST(SparseGridTest, BlocksBeforeAStoredBrickAreActive) {
  SparseGrid grid(0.1f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}}).ok());
  GridView v = grid.view();
  const int ox = -grid.index_min()[0], oy = -grid.index_min()[1], oz = -grid.index_min()[2];
  EXPECT_TRUE(v.BlockActive(ox, oy, oz));
  EXPECT_TRUE(v.BlockActive(ox - 1, oy - 1, oz - 1));  // its cells' +1 corners are in (0,0,0)
  EXPECT_FALSE(v.BlockActive(ox + 1, oy, oz));
  EXPECT_FALSE(v.BlockActive(ox - 2, oy, oz));
}

TEST(SparseGridTest, RejectsBoundsBeyondTheIndexLimit) {
  SparseGrid grid(0.01f);
  auto s = grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {100000, 100000, 100000}});
  EXPECT_EQ(s.status().code(), absl::StatusCode::kResourceExhausted);
}

TEST(SparseGridTest, ReportsMemory) {
  SparseGrid grid(0.02f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {0, 1, 0}}).ok());
  const GridMemory m = grid.Memory();
  EXPECT_EQ(m.bricks, 2);
  EXPECT_EQ(m.parameter_bytes, 2 * 512 * 28 * 4);
  EXPECT_GT(m.index_bytes, 0);
}

}  // namespace
}  // namespace plx

// The PLY export of a map's surface points, and its cancellation (the daemon's Export stops
// within a few bricks when its call is cancelled).
#include "core/formats/ply_export.h"

#include <gtest/gtest.h>

#include "gmock/gmock.h"
#include "tests/grid_fill.h"

namespace plx {
namespace {

PlenoxelMap MapWithBricks(int n) {
  PlenoxelMap map(0.05f);
  std::vector<BrickCoord> bricks;
  for (int i = 0; i < n; ++i) bricks.push_back({i, 0, 0});
  EXPECT_TRUE(map.grid.AllocateBricks(bricks).ok());
  int i = 0;
  // Alternating density: every dense vertex has an empty neighbour, so every one is a point.
  testing::FillDensity(map.grid, [&] { return (i++ % 2) ? 10.0f : 0.0f; });
  return map;
}

TEST(PlyExportTest, WritesOnePointPerSurfaceVertex) {
  const PlenoxelMap map = MapWithBricks(2);
  const absl::StatusOr<PlyExport> ply = ExportSurfacePointsPly(map, 5.0f);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_EQ(ply->points, 512);
  EXPECT_THAT(ply->bytes, ::testing::HasSubstr("element vertex 512\n"));
}

TEST(PlyExportTest, ACancelledExportStopsEarly) {
  const PlenoxelMap map = MapWithBricks(64);
  int asked = 0;
  const absl::StatusOr<PlyExport> ply =
      ExportSurfacePointsPly(map, 5.0f, [&] { return ++asked > 2; });
  EXPECT_EQ(ply.status().code(), absl::StatusCode::kCancelled) << ply.status();
  EXPECT_EQ(asked, 3);  // every 8 bricks: stopped after 16 of the 64
}

}  // namespace
}  // namespace plx

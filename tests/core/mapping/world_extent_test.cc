// The world extent (core/common/world_extent.h): poses and bricks beyond it are refused where
// they enter the engine, so no brick coordinate wraps around and every map that can be built
// can be saved and loaded again (the map-file round trip at the extent's edges is in
// tests/core/formats/map_file_test.cc).
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/world_extent.h"
#include "core/geometry/world_pose.h"
#include "core/grid/sparse_grid.h"
#include "core/mapping/brick_allocation.h"
#include "core/mapping/training_set.h"
#include "gmock/gmock.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

TEST(WorldExtentTest, PosesInsideTheExtentPassAndOthersNameTheField) {
  const double e = kWorldExtentMeters;
  EXPECT_TRUE(CheckPoseInsideWorld(SE3(Eigen::Quaterniond::Identity(), {e, -e, 0.0}), "p").ok());
  for (const Eigen::Vector3d& t : {Eigen::Vector3d(1e10, 0, 0), Eigen::Vector3d(0, -e - 1.0, 0),
                                   Eigen::Vector3d(0, 0, 2 * e)}) {
    const absl::Status s =
        CheckPoseInsideWorld(SE3(Eigen::Quaterniond::Identity(), t), "frame.pose");
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << t.transpose();
    EXPECT_THAT(s.message(), HasSubstr("frame.pose: translation"));
    EXPECT_THAT(s.message(), HasSubstr("outside the world extent of +-10000 m"));
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(CheckPoseInsideWorld(SE3(Eigen::Quaterniond::Identity(), {nan, 0, 0}), "q").message(),
              HasSubstr("q: not finite"));
}

// The brick range holds exactly the bricks that contain a point within the extent.
TEST(WorldExtentTest, BrickRangeCoversTheExtentAndNoMore) {
  for (float voxel : {0.001f, 0.02f, 0.0173f, 1.0f}) {
    SCOPED_TRACE(voxel);
    const BrickRange r = SparseGrid::WorldBrickRange(voxel);
    const double brick = static_cast<double>(voxel) * 8;
    EXPECT_LE(r.lo * brick, -kWorldExtentMeters);
    EXPECT_GT((r.lo + 1) * brick, -kWorldExtentMeters);
    EXPECT_LE(r.hi * brick, kWorldExtentMeters);
    EXPECT_GT((r.hi + 1) * brick, kWorldExtentMeters);
  }
  // Whatever the voxel size, 8 vertices per brick stay far inside int32.
  const BrickRange tiny = SparseGrid::WorldBrickRange(1e-30f);
  EXPECT_LE(tiny.hi * 8 * 2, int64_t{std::numeric_limits<int32_t>::max()});
  EXPECT_GE(tiny.lo * 8 * 2, int64_t{std::numeric_limits<int32_t>::min()});
}

TEST(WorldExtentTest, AllocateBricksRefusesBricksOutsideTheWorldAndAddsNone) {
  const float voxel = 0.02f;
  const BrickRange r = SparseGrid::WorldBrickRange(voxel);
  const int32_t hi = static_cast<int32_t>(r.hi), lo = static_cast<int32_t>(r.lo);
  SparseGrid grid(voxel);
  // At the edges: accepted.
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{hi, hi, hi}, {hi - 1, hi, hi}}).ok());
  SparseGrid other(voxel);
  ASSERT_TRUE(other.AllocateBricks(std::vector<BrickCoord>{{lo, lo, lo}, {lo, lo + 1, lo}}).ok());
  // One past them, or a coordinate a far pose would wrap to: refused, the grid unchanged.
  for (const BrickCoord& outside :
       {BrickCoord{hi + 1, hi, hi}, BrickCoord{lo, lo - 1, lo},
        BrickCoord{std::numeric_limits<int32_t>::min(), 0, 0}}) {
    const absl::StatusOr<int64_t> added =
        grid.AllocateBricks(std::vector<BrickCoord>{{hi, hi - 1, hi}, outside});
    EXPECT_EQ(added.status().code(), absl::StatusCode::kInvalidArgument) << added.status();
    EXPECT_THAT(added.status().message(), HasSubstr("outside the world extent"));
    EXPECT_EQ(grid.num_bricks(), 2);
  }
  EXPECT_EQ(grid.FindBrick({hi, hi - 1, hi}), -1);
}

TEST(WorldExtentTest, IndexBoundsOutsideTheWorldAreRefused) {
  SparseGrid grid(0.02f);
  const BrickRange r = SparseGrid::WorldBrickRange(0.02f);
  const int32_t hi = static_cast<int32_t>(r.hi);
  EXPECT_TRUE(grid.SetIndexBounds({hi - 10, 0, 0}, {10 + 1 + SparseGrid::kIndexGrowthMargin, 1, 1})
                  .ok());
  SparseGrid wrapped(0.02f);
  const absl::Status s =
      wrapped.SetIndexBounds({std::numeric_limits<int32_t>::max() - 3, 0, 0}, {8, 1, 1});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
}

// A keyframe 10^10 m away used to give bricks at wrapped-around coordinates; its depth is now
// outside the world, so it allocates nothing.
TEST(WorldExtentTest, DepthBeyondTheWorldAllocatesNoBricks) {
  PinholeIntrinsics k{50, 50, 20, 15, 40, 30};
  DepthImage depth(40, 30, 1, 2.0f);
  const SE3 far(Eigen::Quaterniond::Identity(), {1e10, 0, 0});
  EXPECT_TRUE(BricksNearSurface(depth, far, k, 0.02f, AllocationOptions()).empty());
  // A camera looking outwards at a wall on the edge keeps only the bricks inside.
  const SE3 edge(Eigen::Quaterniond::Identity(), {0, 0, kWorldExtentMeters - 3.0});
  DepthImage deep(40, 30, 1, 3.0f);
  const std::vector<BrickCoord> bricks =
      BricksNearSurface(deep, edge, k, 0.02f, AllocationOptions());
  EXPECT_FALSE(bricks.empty());
  for (const BrickCoord& b : bricks) {
    EXPECT_TRUE(SparseGrid::CheckBrickInsideWorld(b, 0.02f).ok())
        << b.x << " " << b.y << " " << b.z;
  }
}

TEST(WorldExtentTest, KeyframesOutsideTheWorldAreRefused) {
  PinholeIntrinsics k{50, 50, 20, 15, 40, 30};
  RgbdFrame frame;
  frame.color = ColorImage(40, 30, 3, 0.5f);
  frame.depth = DepthImage(40, 30, 1, 2.0f);
  TrainingSet set;
  const absl::Status s =
      set.AddFrame(frame, SE3(Eigen::Quaterniond::Identity(), {1e10, 0, 0}), k, 10.0);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(s.message(), HasSubstr("outside the world extent"));
  EXPECT_EQ(set.num_frames(), 0);
  EXPECT_TRUE(set.AddFrame(frame, SE3(), k, 10.0).ok());
}

}  // namespace
}  // namespace plx

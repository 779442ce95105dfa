#include "core/mapping/brick_allocation.h"

#include <gtest/gtest.h>

#include "absl/container/flat_hash_set.h"

namespace plx {
namespace {

// A camera at the origin looking down +z at a wall 2 m away.
TEST(BrickAllocationTest, BricksHugTheMeasuredSurface) {
  PinholeIntrinsics k{50, 50, 20, 15, 40, 30};
  DepthImage depth(40, 30, 1, 2.0f);
  AllocationOptions options;
  options.min_band = 0.1f;
  options.band_sigmas = 0.0f;
  options.pixel_stride = 1;
  const float voxel = 0.02f;  // bricks of 0.16 m
  const std::vector<BrickCoord> bricks = BricksNearSurface(depth, SE3(), k, voxel, options);
  ASSERT_FALSE(bricks.empty());
  for (const BrickCoord& b : bricks) {
    // Brick z-range [0.16 b, 0.16 (b + 1)) must overlap [1.9, 2.1 * range/z].
    const float z0 = b.z * 0.16f, z1 = (b.z + 1) * 0.16f;
    EXPECT_LT(z0, 2.2f);
    EXPECT_GT(z1, 1.9f);
  }
  // Nothing allocated in the free space between camera and wall.
  absl::flat_hash_set<int> zs;
  for (const BrickCoord& b : bricks) zs.insert(b.z);
  EXPECT_FALSE(zs.contains(5));  // 0.8 .. 0.96 m
}

TEST(BrickAllocationTest, InvalidAndFarDepthAllocateNothing) {
  PinholeIntrinsics k{50, 50, 20, 15, 40, 30};
  DepthImage depth(40, 30, 1, 0.0f);
  depth.data[100] = 50.0f;  // beyond max_depth
  AllocationOptions options;
  options.max_depth = 10.0f;
  EXPECT_TRUE(BricksNearSurface(depth, SE3(), k, 0.02f, options).empty());
}

TEST(BrickAllocationTest, BandGrowsWithSensorNoiseAtRange) {
  PinholeIntrinsics k{50, 50, 20, 15, 40, 30};
  AllocationOptions options;
  options.min_band = 0.02f;
  options.pixel_stride = 1;
  auto depth_span = [&](float z) {
    DepthImage depth(40, 30, 1, z);
    int lo = 1 << 30, hi = -(1 << 30);
    for (const BrickCoord& b : BricksNearSurface(depth, SE3(), k, 0.02f, options)) {
      lo = std::min(lo, b.z);
      hi = std::max(hi, b.z);
    }
    return hi - lo + 1;
  };
  EXPECT_GT(depth_span(6.0f), depth_span(1.0f));
}

}  // namespace
}  // namespace plx

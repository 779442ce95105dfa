// The SLAM tracker's options that bound a frame's cost: the rays of a dense check of a feature
// place on a frame that was tracked already, and their validation.
#include <gtest/gtest.h>

#include <limits>

#include "core/slam/slam_tracker.h"

namespace plx {
namespace {

TEST(SlamTrackerOptionsTest, AnOnPathCheckCastsItsShareOfTheRaysWithinBounds) {
  SlamTrackerOptions o;
  ASSERT_TRUE(ValidateSlamTrackerOptions(o).ok());
  o.tracker.rays = 2048;
  EXPECT_EQ(OnPathCheckRays(o), 1024);  // the default share, a half
  o.on_path_check_ray_share = 1.0;
  EXPECT_EQ(OnPathCheckRays(o), 2048);
  o.on_path_check_ray_share = 0.3;
  EXPECT_EQ(OnPathCheckRays(o), 614);  // rounded
  // Never fewer than 256 rays (a judgement at the sensor's noise needs samples), never more
  // than the tracker casts.
  o.on_path_check_ray_share = 0.01;
  EXPECT_EQ(OnPathCheckRays(o), 256);
  o.tracker.rays = 128;
  EXPECT_EQ(OnPathCheckRays(o), 128);
}

TEST(SlamTrackerOptionsTest, AShareOutsideZeroToOneIsRefused) {
  SlamTrackerOptions o;
  for (double share : {0.0, -0.5, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    o.on_path_check_ray_share = share;
    const absl::Status status = ValidateSlamTrackerOptions(o);
    EXPECT_FALSE(status.ok()) << share;
    EXPECT_NE(status.message().find("on_path_check_ray_share"), std::string::npos) << status;
  }
}

}  // namespace
}  // namespace plx

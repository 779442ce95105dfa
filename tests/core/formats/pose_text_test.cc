// Pose text ("tx ty tz qx qy qz qw", the CLI's --pose): parsing, normalisation, the round trip.
#include "core/formats/pose_text.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx {
namespace {

using ::testing::HasSubstr;

TEST(PoseTextTest, ParsesSpacesOrCommasAndNormalises) {
  const absl::StatusOr<SE3> pose = ParsePoseText("1, 2 3\t0 0 0 2");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_EQ(pose->translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(pose->rotation().coeffs(), Eigen::Vector4d(0, 0, 0, 1));
}

TEST(PoseTextTest, FormatThenParseRoundTrips) {
  const SE3 pose(
      Eigen::Quaterniond(Eigen::AngleAxisd(-2.5, Eigen::Vector3d(1, 2, -1).normalized())),
      Eigen::Vector3d(-0.5, 10.25, 3.0));
  const absl::StatusOr<SE3> back = ParsePoseText(FormatPoseText(pose));
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_LT((back->translation() - pose.translation()).norm(), 1e-9);
  EXPECT_LT(back->rotation().angularDistance(pose.rotation()), 1e-8);
}

// Found by fuzz_text_files: components whose squares overflow were normalised into a zero
// quaternion instead of a unit one.
TEST(PoseTextTest, HugeQuaternionComponentsNormalise) {
  const absl::StatusOr<SE3> pose = ParsePoseText("0 0 0 0 1e200 0 1e200");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_NEAR(pose->rotation().norm(), 1.0, 1e-12);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  EXPECT_LT(pose->rotation().angularDistance(expected), 1e-12);
}

TEST(PoseTextTest, RejectsWrongCountNonFiniteAndZeroQuaternion) {
  EXPECT_THAT(ParsePoseText("0 0 0 0 0 1").status().message(), HasSubstr("7 numbers"));
  EXPECT_THAT(ParsePoseText("0 0 nan 0 0 0 1").status().message(),
              HasSubstr("\"nan\" is not a finite number"));
  EXPECT_THAT(ParsePoseText("0 0 0 0 0 0 0").status().message(), HasSubstr("quaternion is zero"));
  EXPECT_THAT(ParsePoseText("0 0 0 1e-300 0 0 0").status().message(),
              HasSubstr("quaternion is zero"));
}

}  // namespace
}  // namespace plx

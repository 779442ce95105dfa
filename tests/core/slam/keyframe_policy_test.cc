// Keyframe selection on crafted motions: each rule fires on its own, and a camera that comes
// back to a mapped place adds nothing.
#include "core/slam/keyframe_policy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace plx {
namespace {

SE3 At(double x, double yaw_deg = 0.0) {
  const double yaw = yaw_deg * M_PI / 180.0;
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())),
             Eigen::Vector3d(x, 0.0, 0.0));
}

TEST(KeyframePolicyTest, StillCameraMakesNoKeyframe) {
  const KeyframePolicy p;
  const std::vector<StampedPose> keyframes = {{0.0, At(0.0)}};
  const KeyframeDecision d = DecideKeyframe(p, keyframes, At(0.02, 2.0), 30.0, 0.05);
  EXPECT_FALSE(d.keyframe) << d.reason;
}

TEST(KeyframePolicyTest, TranslationRotationAndUnmappedViewEachFire) {
  const KeyframePolicy p;  // 0.10 m, 0.26 rad, 15 %
  const std::vector<StampedPose> keyframes = {{0.0, At(0.0)}};
  const KeyframeDecision moved = DecideKeyframe(p, keyframes, At(0.11), 1.0, 0.0);
  EXPECT_TRUE(moved.keyframe);
  EXPECT_NE(moved.reason.find("m from every keyframe"), std::string::npos) << moved.reason;
  const KeyframeDecision turned = DecideKeyframe(p, keyframes, At(0.0, 16.0), 1.0, 0.0);
  EXPECT_TRUE(turned.keyframe);
  EXPECT_NE(turned.reason.find("turned"), std::string::npos) << turned.reason;
  const KeyframeDecision unmapped = DecideKeyframe(p, keyframes, At(0.0), 1.0, 0.2);
  EXPECT_TRUE(unmapped.keyframe);
  EXPECT_NE(unmapped.reason.find("unmapped"), std::string::npos) << unmapped.reason;
  // Just inside every limit.
  EXPECT_FALSE(DecideKeyframe(p, keyframes, At(0.09, 14.0), 1.0, 0.14).keyframe);
}

TEST(KeyframePolicyTest, ComingBackToAMappedPlaceAddsNothing) {
  const KeyframePolicy p;
  // A path out and back: the last keyframe is far away, an earlier one covers the view.
  const std::vector<StampedPose> keyframes = {{0.0, At(0.0)}, {1.0, At(0.15)}, {2.0, At(0.30)}};
  EXPECT_FALSE(DecideKeyframe(p, keyframes, At(0.01, 3.0), 3.0, 0.0).keyframe);
  // A keyframe near in position but turned away does not cover the view.
  const std::vector<StampedPose> turned = {{0.0, At(0.0, 90.0)}};
  EXPECT_TRUE(DecideKeyframe(p, turned, At(0.0), 1.0, 0.0).keyframe);
}

TEST(KeyframePolicyTest, TimeRuleOnlyWhenAsked) {
  KeyframePolicy p;
  const std::vector<StampedPose> keyframes = {{0.0, At(0.0)}};
  EXPECT_FALSE(DecideKeyframe(p, keyframes, At(0.0), 100.0, 0.0).keyframe);
  p.max_interval_s = 2.0;
  EXPECT_FALSE(DecideKeyframe(p, keyframes, At(0.0), 1.5, 0.0).keyframe);
  EXPECT_TRUE(DecideKeyframe(p, keyframes, At(0.0), 2.5, 0.0).keyframe);
}

TEST(KeyframePolicyTest, BadThresholdsAreRejected) {
  KeyframePolicy p;
  p.max_translation_m = -1.0;
  EXPECT_EQ(ValidateKeyframePolicy(p).code(), absl::StatusCode::kInvalidArgument);
  p = KeyframePolicy();
  p.max_rotation_rad = NAN;
  EXPECT_EQ(ValidateKeyframePolicy(p).code(), absl::StatusCode::kInvalidArgument);
  p = KeyframePolicy();
  p.max_unmapped_fraction = 1.5;
  EXPECT_EQ(ValidateKeyframePolicy(p).code(), absl::StatusCode::kInvalidArgument);
  p = KeyframePolicy();
  p.max_interval_s = INFINITY;
  EXPECT_EQ(ValidateKeyframePolicy(p).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(ValidateKeyframePolicy(KeyframePolicy()).ok());
}

}  // namespace
}  // namespace plx

#include "core/slam/pose_fusion.h"

#include <gtest/gtest.h>

#include <string>
#include <utility>

namespace plx {
namespace pose_fusion_test {

SE3 At(double x) { return SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, 0, 0)); }

TrackingResult Map(TrackingState state, TrackingCause cause, double x) {
  TrackingResult r;
  r.state = state;
  r.cause = cause;
  r.pose = At(x);
  r.reason = "map says so";
  return r;
}

OdometryPose Odometry(bool ok, double x) { return OdometryPose{At(x), ok, ok ? "" : "blind"}; }

TEST(PoseFusionTest, AnOkMapWinsAndMayMakeAKeyframe) {
  // 6 cm apart: the drift the map corrects (not a jump: AnOkMapThatJumpedAway...).
  const FusedPose f = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.0),
                                Odometry(true, 1.06), PoseFusionOptions());
  EXPECT_EQ(f.state, SlamState::kOk);
  EXPECT_EQ(f.source, PoseSource::kMap);
  EXPECT_EQ(f.pose.translation().x(), 1.0);
  EXPECT_TRUE(f.may_be_keyframe);
  EXPECT_FALSE(f.confirm);
  // No odometry at all (the first frame after a LOST one): the map alone, as before it existed.
  const FusedPose alone = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.0),
                                    std::nullopt, PoseFusionOptions());
  EXPECT_TRUE(alone.may_be_keyframe);
  EXPECT_FALSE(alone.confirm);
}

TEST(PoseFusionTest, AnOkMapThatJumpedAwayFromTheOdometryIsNotTaken) {
  // The map tracker started at the odometry's pose and came back OK 26 cm away: another basin.
  const FusedPose jumped = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.26),
                                     Odometry(true, 1.0), PoseFusionOptions());
  EXPECT_EQ(jumped.state, SlamState::kDegraded);
  EXPECT_EQ(jumped.source, PoseSource::kOdometry);
  EXPECT_EQ(jumped.pose.translation().x(), 1.0);
  EXPECT_FALSE(jumped.may_be_keyframe);
  EXPECT_FALSE(jumped.confirm);
  EXPECT_NE(jumped.reason.find("jumped 0.26 m"), std::string::npos) << jumped.reason;
  // The features agree with the odometry: the map lags the view, a keyframe may fix it.
  EXPECT_TRUE(ApplyFeatureCheck(jumped, true, true).may_be_keyframe);
  // A turn away from the odometry's counts too.
  const SE3 turned(Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(1.0, 0, 0));
  TrackingResult map = Map(TrackingState::kOk, TrackingCause::kNone, 1.0);
  map.pose = turned;
  EXPECT_EQ(FusePoses(map, Odometry(true, 1.0), PoseFusionOptions()).source,
            PoseSource::kOdometry);
  // The drift the map corrects after a carry (8 cm here) is the map's to correct: OK.
  const FusedPose corrected = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.08),
                                        Odometry(true, 1.0), PoseFusionOptions());
  EXPECT_EQ(corrected.state, SlamState::kOk);
  EXPECT_EQ(corrected.source, PoseSource::kMap);
  EXPECT_TRUE(corrected.may_be_keyframe);
}

TEST(PoseFusionTest, AnOkMapAfterTheOdometryFailedWaitsForConfirmation) {
  // A jump in the stream: the odometry gives up, the map tracker settles somewhere it explains.
  const FusedPose f = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.0),
                                Odometry(false, 3.0), PoseFusionOptions());
  EXPECT_EQ(f.state, SlamState::kOk);
  EXPECT_EQ(f.source, PoseSource::kMap);
  EXPECT_EQ(f.pose.translation().x(), 1.0);
  EXPECT_TRUE(f.confirm);
  EXPECT_FALSE(f.may_be_keyframe);
  EXPECT_NE(f.reason.find("blind"), std::string::npos) << f.reason;
}

TEST(PoseFusionTest, UnmappedViewWithOdometryIsDegradedButMayMakeAKeyframe) {
  // The map sees too little to say anything (LOST for few rays): the odometry carries the pose.
  const FusedPose lost = FusePoses(Map(TrackingState::kLost, TrackingCause::kFewValidRays, 0.0),
                                   Odometry(true, 2.0), PoseFusionOptions());
  EXPECT_EQ(lost.state, SlamState::kDegraded);
  EXPECT_EQ(lost.source, PoseSource::kOdometry);
  EXPECT_EQ(lost.pose.translation().x(), 2.0);
  EXPECT_TRUE(lost.may_be_keyframe);
  EXPECT_NE(lost.reason.find("pose from odometry"), std::string::npos) << lost.reason;
  // A few rays, near the odometry: the map's absolute pose.
  const FusedPose near = FusePoses(
      Map(TrackingState::kDegraded, TrackingCause::kFewValidRays, 2.03), Odometry(true, 2.0),
      PoseFusionOptions());
  EXPECT_EQ(near.source, PoseSource::kMap);
  EXPECT_EQ(near.pose.translation().x(), 2.03);
  EXPECT_TRUE(near.may_be_keyframe);
  // A few rays that slid away from the odometry: the odometry's.
  const FusedPose slid = FusePoses(
      Map(TrackingState::kDegraded, TrackingCause::kFewValidRays, 2.2), Odometry(true, 2.0),
      PoseFusionOptions());
  EXPECT_EQ(slid.source, PoseSource::kOdometry);
  EXPECT_EQ(slid.pose.translation().x(), 2.0);
}

TEST(PoseFusionTest, AMapThatDisagreesWithTheFrameNeverFeedsTheMap) {
  for (TrackingCause cause : {TrackingCause::kHighResidual, TrackingCause::kDiverged}) {
    const FusedPose f = FusePoses(Map(TrackingState::kLost, cause, 0.0), Odometry(true, 1.0),
                                  PoseFusionOptions());
    EXPECT_EQ(f.state, SlamState::kDegraded);
    EXPECT_EQ(f.source, PoseSource::kOdometry);
    EXPECT_FALSE(f.may_be_keyframe);
  }
}

TEST(PoseFusionTest, FeaturesThatAgreeWithTheOdometryLetAFrameTheMapLagsBecomeAKeyframe) {
  const FusedPose f = FusePoses(Map(TrackingState::kDegraded, TrackingCause::kHighResidual, 0.0),
                                Odometry(true, 0.01), PoseFusionOptions());
  ASSERT_FALSE(f.may_be_keyframe);
  const CheckedPose agreed = ApplyFeatureCheck(f, /*features_found=*/true, /*agree=*/true);
  EXPECT_EQ(agreed.state, SlamState::kDegraded) << "the map still does not explain the frame";
  EXPECT_TRUE(agreed.may_be_keyframe);
  EXPECT_NE(agreed.reason.find("features confirm"), std::string::npos) << agreed.reason;
  for (const auto& [found, agree] : {std::pair{false, false}, std::pair{true, false}}) {
    const CheckedPose c = ApplyFeatureCheck(f, found, agree);
    EXPECT_EQ(c.state, SlamState::kDegraded);
    EXPECT_FALSE(c.may_be_keyframe) << "found " << found << " agree " << agree;
    EXPECT_EQ(c.reason, f.reason);
  }
}

TEST(PoseFusionTest, AMapPoseToConfirmIsOkOnlyWhenTheFeaturesAgree) {
  const FusedPose f = FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 0.0),
                                Odometry(false, 0.0), PoseFusionOptions());
  ASSERT_TRUE(f.confirm);
  const CheckedPose agreed = ApplyFeatureCheck(f, true, true);
  EXPECT_EQ(agreed.state, SlamState::kOk);
  EXPECT_TRUE(agreed.may_be_keyframe);
  for (const auto& [found, agree] : {std::pair{false, false}, std::pair{true, false}}) {
    const CheckedPose c = ApplyFeatureCheck(f, found, agree);
    EXPECT_EQ(c.state, SlamState::kDegraded);
    EXPECT_FALSE(c.may_be_keyframe);
  }
}

TEST(PoseFusionTest, APoseChainedToAnUnconfirmedOneNeedsConfirmingAndIsNoKeyframe) {
  // The odometry tracked from the previous frame and the map agrees, but the previous frame's
  // pose was one the features did not confirm: so is this one.
  const FusedPose f = ChainedToUnconfirmedPose(
      FusePoses(Map(TrackingState::kOk, TrackingCause::kNone, 1.0), Odometry(true, 1.0),
                PoseFusionOptions()));
  EXPECT_EQ(f.state, SlamState::kOk);
  EXPECT_EQ(f.pose.translation().x(), 1.0);
  EXPECT_TRUE(f.confirm);
  EXPECT_FALSE(f.may_be_keyframe);
  EXPECT_NE(f.reason.find("did not confirm"), std::string::npos) << f.reason;
  const CheckedPose agreed = ApplyFeatureCheck(f, true, true);
  EXPECT_EQ(agreed.state, SlamState::kOk);
  EXPECT_TRUE(agreed.may_be_keyframe);
  EXPECT_FALSE(agreed.unconfirmed) << "confirmed: the chain ends";
  const CheckedPose refused = ApplyFeatureCheck(f, false, false);
  EXPECT_EQ(refused.state, SlamState::kDegraded);
  EXPECT_FALSE(refused.may_be_keyframe);
  EXPECT_TRUE(refused.unconfirmed) << "the chain goes on";
  // An unmapped view carried by the odometry (a keyframe otherwise): no keyframe either.
  const FusedPose unmapped = ChainedToUnconfirmedPose(
      FusePoses(Map(TrackingState::kLost, TrackingCause::kFewValidRays, 0.0), Odometry(true, 2.0),
                PoseFusionOptions()));
  EXPECT_EQ(unmapped.state, SlamState::kDegraded);
  EXPECT_FALSE(unmapped.may_be_keyframe);
  EXPECT_TRUE(unmapped.confirm);
  // A LOST frame is a prediction, not a pose to confirm: unchanged.
  const FusedPose lost = ChainedToUnconfirmedPose(FusePoses(
      Map(TrackingState::kLost, TrackingCause::kFewValidRays, 1.0), std::nullopt,
      PoseFusionOptions()));
  EXPECT_EQ(lost.state, SlamState::kLost);
  EXPECT_FALSE(lost.confirm);
}

TEST(PoseFusionTest, WithoutATrustedOdometryTheMapDecidesAlone) {
  const FusedPose degraded =
      FusePoses(Map(TrackingState::kDegraded, TrackingCause::kFewValidRays, 1.0),
                Odometry(false, 5.0), PoseFusionOptions());
  EXPECT_EQ(degraded.state, SlamState::kDegraded);
  EXPECT_EQ(degraded.source, PoseSource::kMap);
  EXPECT_FALSE(degraded.may_be_keyframe);
  EXPECT_NE(degraded.reason.find("odometry: blind"), std::string::npos) << degraded.reason;
  const FusedPose lost = FusePoses(Map(TrackingState::kLost, TrackingCause::kFewValidRays, 1.0),
                                   std::nullopt, PoseFusionOptions());
  EXPECT_EQ(lost.state, SlamState::kLost);
  EXPECT_EQ(lost.source, PoseSource::kPrediction);
  EXPECT_EQ(lost.pose.translation().x(), 1.0);  // the map tracker's prediction
  EXPECT_FALSE(lost.may_be_keyframe);
}

}  // namespace pose_fusion_test
}  // namespace plx

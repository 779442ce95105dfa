// The pose codec shared by the daemon and the CLI: the qw >= 0 convention on the wire, the
// round trip, and the errors that name the offending field.
#include "proto/pose_codec.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx {
namespace {

namespace pb = ::plenoxd::v1;
using ::testing::HasSubstr;

SE3 SomePose() {
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized())),
             Eigen::Vector3d(0.25, -1.5, 3.0));
}

TEST(PoseCodecTest, WritesUnitQuaternionWithNonNegativeQw) {
  const SE3 pose = SomePose();
  const Eigen::Quaterniond& q = pose.rotation();
  ASSERT_GT(q.w(), 0.0);
  // -q is the same rotation: SE3 keeps the sign it was given, the wire does not.
  const SE3 flipped(Eigen::Quaterniond(-q.w(), -q.x(), -q.y(), -q.z()), pose.translation());
  ASSERT_LT(flipped.rotation().w(), 0.0);
  for (const SE3& p : {pose, flipped}) {
    pb::Pose message;
    PoseToProto(p, &message);
    EXPECT_NEAR(message.qw(), q.w(), 1e-12);
    EXPECT_NEAR(message.qx(), q.x(), 1e-12);
    EXPECT_NEAR(message.qy(), q.y(), 1e-12);
    EXPECT_NEAR(message.qz(), q.z(), 1e-12);
    EXPECT_EQ(message.tz(), 3.0);
  }
}

TEST(PoseCodecTest, RoundTripKeepsThePose) {
  const SE3 pose = SomePose();
  pb::Pose message;
  PoseToProto(pose, &message);
  const absl::StatusOr<SE3> back = PoseFromProto(message, "pose");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_LT((back->translation() - pose.translation()).norm(), 1e-12);
  EXPECT_LT(back->rotation().angularDistance(pose.rotation()), 1e-9);
  // Encoding the decoded pose gives the same message: one convention both ways.
  pb::Pose again;
  PoseToProto(*back, &again);
  EXPECT_EQ(again.SerializeAsString(), message.SerializeAsString());
}

TEST(PoseCodecTest, NormalisesOnReceipt) {
  pb::Pose message;
  message.set_qw(-2.0);  // the identity, scaled by -2
  const absl::StatusOr<SE3> pose = PoseFromProto(message, "pose");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_NEAR(pose->rotation().norm(), 1.0, 1e-12);
  EXPECT_LT(pose->rotation().angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
  pb::Pose out;
  PoseToProto(*pose, &out);
  EXPECT_EQ(out.qw(), 1.0);
}

// Found by fuzz_frame_proto: a quaternion of 1e200s (finite, so accepted) was normalised into
// a zero quaternion, a client pose with no rotation at all.
TEST(PoseCodecTest, NormalisesHugeQuaternions) {
  pb::Pose message;
  message.set_qw(1e200);
  message.set_qz(1e200);
  const absl::StatusOr<SE3> pose = PoseFromProto(message, "pose");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_NEAR(pose->rotation().norm(), 1.0, 1e-12);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  EXPECT_LT(pose->rotation().angularDistance(expected), 1e-12);
}

TEST(PoseCodecTest, RejectsNonFiniteAndZeroQuaternions) {
  pb::Pose message;
  message.set_qw(1.0);
  message.set_ty(std::numeric_limits<double>::quiet_NaN());
  absl::StatusOr<SE3> pose = PoseFromProto(message, "frame.pose");
  EXPECT_EQ(pose.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(pose.status().message(), HasSubstr("frame.pose.ty: not finite"));

  pose = PoseFromProto(pb::Pose(), "initial_pose");
  EXPECT_EQ(pose.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(pose.status().message(), HasSubstr("initial_pose: the quaternion is zero"));
}

}  // namespace
}  // namespace plx

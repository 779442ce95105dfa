// The frame and map-name codecs (proto/frame_codec.h, proto/map_codec.h): a frame the CLI would
// send comes back through CheckFrame and DecodeCheckedFrame as the same images, calibration and
// pose; refusals are INVALID_ARGUMENT (RESOURCE_EXHAUSTED over the pixel limit) naming the field.
#include "proto/frame_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "core/io/image_io.h"
#include "proto/map_codec.h"

namespace plx {
namespace {

using ::testing::StartsWith;

constexpr int kW = 8, kH = 6;
constexpr double kDepthScale = 1000.0;

pb::Frame RawFrame() {
  ColorImage color(kW, kH, 3);
  DepthImage depth(kW, kH, 1);
  for (size_t i = 0; i < color.data.size(); ++i) color.data[i] = static_cast<float>(i % 256) / 255;
  for (size_t i = 0; i < depth.data.size(); ++i) depth.data[i] = 0.5f + 0.001f * i;
  pb::Frame f;
  f.set_camera_id("cam");
  f.set_timestamp(12.5);
  pb::Intrinsics* k = f.mutable_intrinsics();
  k->set_fx(10);
  k->set_fy(11);
  k->set_cx(4);
  k->set_cy(3);
  k->set_width(kW);
  k->set_height(kH);
  k->set_depth_scale(kDepthScale);
  f.set_color(ColorImageToRgb8Bytes(color));
  f.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
  f.set_depth(DepthImageToU16Bytes(depth, kDepthScale));
  f.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
  return f;
}

std::string Message(const absl::Status& s) { return std::string(s.message()); }

TEST(FrameCodecTest, RawFrameRoundTrips) {
  pb::Frame f = RawFrame();
  const SE3 pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3));
  PoseToProto(pose, f.mutable_pose());
  absl::StatusOr<CheckedFrame> checked = CheckFrame(f, "frame", true, int64_t{1} << 20);
  ASSERT_TRUE(checked.ok()) << checked.status();
  ASSERT_TRUE(checked->client_pose.has_value());
  EXPECT_TRUE(checked->client_pose->translation().isApprox(pose.translation()));
  absl::StatusOr<DecodedFrame> decoded = DecodeCheckedFrame(*std::move(checked));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->camera_id, "cam");
  EXPECT_EQ(decoded->frame.timestamp, 12.5);
  EXPECT_EQ(decoded->calibration.pinhole.fx, 10);
  EXPECT_EQ(decoded->calibration.pinhole.width, kW);
  EXPECT_EQ(decoded->calibration.depth_scale, kDepthScale);
  // Re-encoding the decoded images gives the wire bytes back (8- and 16-bit quantisation).
  EXPECT_EQ(ColorImageToRgb8Bytes(decoded->frame.color), f.color());
  EXPECT_EQ(DepthImageToU16Bytes(decoded->frame.depth, kDepthScale), f.depth());
}

TEST(FrameCodecTest, RequiredPoseIsNamed) {
  absl::StatusOr<CheckedFrame> checked = CheckFrame(RawFrame(), "frame[3]", true, 1 << 20);
  ASSERT_FALSE(checked.ok());
  EXPECT_EQ(checked.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(checked.status()), StartsWith("frame[3].pose: required"));
  EXPECT_TRUE(CheckFrame(RawFrame(), "frame", false, 1 << 20).ok());
}

TEST(FrameCodecTest, WrongByteCountAndPixelLimitAreRefused) {
  pb::Frame f = RawFrame();
  f.mutable_color()->pop_back();
  absl::StatusOr<CheckedFrame> checked = CheckFrame(f, "frame", false, 1 << 20);
  ASSERT_FALSE(checked.ok());
  EXPECT_EQ(checked.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(checked.status()), StartsWith("frame.color: raw RGB8 needs"));
  checked = CheckFrame(RawFrame(), "frame", false, kW * kH - 1);
  ASSERT_FALSE(checked.ok());
  EXPECT_EQ(checked.status().code(), absl::StatusCode::kResourceExhausted);
}

TEST(FrameCodecTest, IntrinsicsWithoutDepthScaleTakeTheDefault) {
  pb::Intrinsics k = RawFrame().intrinsics();
  k.set_depth_scale(0);
  absl::StatusOr<CameraCalibration> c = IntrinsicsFromProto(k, "intrinsics", false);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->depth_scale, 1000.0);
  k.set_width(16385);
  c = IntrinsicsFromProto(k, "intrinsics", false);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(Message(c.status()), StartsWith("intrinsics: image size 16385x"));
}

TEST(MapCodecTest, MapNames) {
  EXPECT_TRUE(CheckMapName("room_0.v-2", "name").ok());
  EXPECT_TRUE(CheckMapName(std::string(64, 'a'), "name").ok());
  for (const std::string& bad : {std::string(), std::string(65, 'a'), std::string(".hidden"),
                                 std::string("a/b"), std::string("a b")}) {
    const absl::Status s = CheckMapName(bad, "map");
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_THAT(Message(s), StartsWith("map: map names ")) << bad;
  }
}

}  // namespace
}  // namespace plx

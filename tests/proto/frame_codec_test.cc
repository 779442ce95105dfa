// The frame and map-name codecs (proto/frame_codec.h, proto/map_codec.h): a frame the CLI sends
// (FrameToProto, in every encoding) comes back through CheckFrame and DecodeCheckedFrame as the
// same images, calibration and pose; refusals are INVALID_ARGUMENT (RESOURCE_EXHAUSTED over the
// pixel limit) naming the field.
#include "proto/frame_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>

#include "absl/strings/str_cat.h"
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

// An RgbdFrame whose images are exactly representable on the wire: colour in 8-bit steps,
// depth in steps of 1 / kDepthScale (so PNG and raw round trips are exact).
RgbdFrame QuantisedFrame() {
  RgbdFrame f;
  f.timestamp = 7.125;
  f.color = ColorImage(kW, kH, 3);
  f.depth = DepthImage(kW, kH, 1);
  for (size_t i = 0; i < f.color.data.size(); ++i) f.color.data[i] = (37 * i % 256) / 255.0f;
  for (size_t i = 0; i < f.depth.data.size(); ++i) {
    f.depth.data[i] = i == 5 ? 0.0f : static_cast<float>((800 + 13 * i) / kDepthScale);
  }
  return f;
}

CameraCalibration Calibration() {
  CameraCalibration c;
  c.pinhole = PinholeIntrinsics{9.5, 10.25, 3.75, 2.5, kW, kH};
  c.depth_scale = kDepthScale;
  return c;
}

absl::StatusOr<DecodedFrame> ThroughTheDaemon(const pb::Frame& f) {
  absl::StatusOr<CheckedFrame> checked = CheckFrame(f, "frame", false, 1 << 20);
  if (!checked.ok()) return checked.status();
  return DecodeCheckedFrame(*std::move(checked));
}

TEST(FrameCodecTest, EncodedFramesDecodeToTheSameFrame) {
  const RgbdFrame frame = QuantisedFrame();
  const SE3 pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX())),
                 Eigen::Vector3d(-1, 0.5, 2));
  for (const FrameEncoding encoding :
       {FrameEncoding{pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16},
        FrameEncoding{pb::COLOR_ENCODING_RAW_RGB8, pb::DEPTH_ENCODING_RAW_U16},
        FrameEncoding{pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_RAW_U16},
        FrameEncoding{pb::COLOR_ENCODING_RAW_RGB8, pb::DEPTH_ENCODING_PNG16}}) {
    SCOPED_TRACE(absl::StrCat(pb::ColorEncoding_Name(encoding.color), " + ",
                              pb::DepthEncoding_Name(encoding.depth)));
    const absl::StatusOr<pb::Frame> wire = FrameToProto(frame, Calibration(), pose, encoding, "c1");
    ASSERT_TRUE(wire.ok()) << wire.status();
    EXPECT_EQ(wire->color_encoding(), encoding.color);
    EXPECT_EQ(wire->depth_encoding(), encoding.depth);
    const absl::StatusOr<DecodedFrame> back = ThroughTheDaemon(*wire);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(back->camera_id, "c1");
    EXPECT_EQ(back->frame.timestamp, frame.timestamp);
    EXPECT_EQ(back->calibration.pinhole, Calibration().pinhole);
    EXPECT_EQ(back->calibration.depth_scale, kDepthScale);
    ASSERT_TRUE(back->client_pose.has_value());
    EXPECT_LT((back->client_pose->translation() - pose.translation()).norm(), 1e-12);
    EXPECT_LT(back->client_pose->rotation().angularDistance(pose.rotation()), 1e-9);
    ASSERT_EQ(back->frame.color.data.size(), frame.color.data.size());
    for (size_t i = 0; i < frame.color.data.size(); ++i) {
      ASSERT_FLOAT_EQ(back->frame.color.data[i], frame.color.data[i]) << i;
    }
    ASSERT_EQ(back->frame.depth.data.size(), frame.depth.data.size());
    for (size_t i = 0; i < frame.depth.data.size(); ++i) {
      ASSERT_NEAR(back->frame.depth.data[i], frame.depth.data[i], 1e-6) << i;
    }
  }
}

TEST(FrameCodecTest, JpegColourDecodesClose) {
  const RgbdFrame frame = QuantisedFrame();
  const absl::StatusOr<pb::Frame> wire =
      FrameToProto(frame, Calibration(), std::nullopt,
                   {pb::COLOR_ENCODING_JPEG, pb::DEPTH_ENCODING_PNG16}, "c1");
  ASSERT_TRUE(wire.ok()) << wire.status();
  EXPECT_FALSE(wire->has_pose());
  const absl::StatusOr<DecodedFrame> back = ThroughTheDaemon(*wire);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_FALSE(back->client_pose.has_value());
  ASSERT_EQ(back->frame.color.data.size(), frame.color.data.size());
  double error = 0.0;
  for (size_t i = 0; i < frame.color.data.size(); ++i) {
    error += std::abs(back->frame.color.data[i] - frame.color.data[i]);
  }
  // Lossy, but the same picture: a wrong channel order or size would be far off.
  EXPECT_LT(error / frame.color.data.size(), 0.25);
}

TEST(FrameCodecTest, UnknownEncodingsAreRefused) {
  const absl::StatusOr<pb::Frame> color =
      FrameToProto(QuantisedFrame(), Calibration(), std::nullopt,
                   {pb::COLOR_ENCODING_UNSPECIFIED, pb::DEPTH_ENCODING_PNG16}, "c1");
  ASSERT_FALSE(color.ok());
  EXPECT_EQ(color.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(color.status()), StartsWith("color_encoding: "));
  const absl::StatusOr<pb::Frame> depth =
      FrameToProto(QuantisedFrame(), Calibration(), std::nullopt,
                   {pb::COLOR_ENCODING_PNG, static_cast<pb::DepthEncoding>(9)}, "c1");
  ASSERT_FALSE(depth.ok());
  EXPECT_EQ(depth.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(depth.status()), StartsWith("depth_encoding: "));
}

TEST(FrameCodecTest, IntrinsicsRoundTrip) {
  pb::Intrinsics wire;
  IntrinsicsToProto(Calibration().pinhole, 5000.0, &wire);
  const absl::StatusOr<CameraCalibration> back = IntrinsicsFromProto(wire, "intrinsics", true);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->pinhole, Calibration().pinhole);
  EXPECT_EQ(back->depth_scale, 5000.0);
}

TEST(FrameCodecTest, ImageSideIsHeldToCoresLimit) {
  pb::Intrinsics k;
  IntrinsicsToProto(PinholeIntrinsics{100, 100, 50, 50, kMaxImageSide, 4}, 1000.0, &k);
  EXPECT_TRUE(IntrinsicsFromProto(k, "intrinsics", true).ok());
  k.set_height(kMaxImageSide + 1);
  const absl::StatusOr<CameraCalibration> c = IntrinsicsFromProto(k, "intrinsics", true);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(c.status()), StartsWith("intrinsics: image size "));
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

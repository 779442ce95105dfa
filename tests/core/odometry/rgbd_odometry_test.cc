#include "core/odometry/rgbd_odometry.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/odometry/odometry_pyramid.h"
#include "core/synthetic/synthetic_scene.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

using ::plx::testing::SyntheticCamera;

OdometryPyramid Pyramid(const RgbdFrame& frame, const PinholeIntrinsics& k) {
  absl::StatusOr<OdometryPyramid> p = BuildOdometryPyramid(frame, k, OdometryPyramidOptions());
  EXPECT_TRUE(p.ok()) << p.status();
  return *std::move(p);
}

struct PoseError {
  double translation_m;
  double rotation_deg;
};

PoseError ErrorOf(const SE3& estimate, const SE3& truth) {
  const SE3 delta = truth.Inverse() * estimate;
  return {delta.translation().norm(),
          Eigen::AngleAxisd(delta.rotation()).angle() * 180.0 / M_PI};
}

// Aligns the view at `current` to the view at `reference` from the identity.
OdometryResult Align(const SE3& reference, const SE3& current, const PinholeIntrinsics& k) {
  const RgbdFrame a = RenderSyntheticView(reference, k);
  const RgbdFrame b = RenderSyntheticView(current, k);
  absl::StatusOr<OdometryResult> r =
      EstimateOdometry(Pyramid(a, k), Pyramid(b, k), SE3::Identity(), OdometryOptions());
  EXPECT_TRUE(r.ok()) << r.status();
  return *r;
}

SE3 Yaw(double degrees) {  // about the camera's y axis (image "down"): a head turn
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(degrees * M_PI / 180.0,
                                                  Eigen::Vector3d::UnitY())),
             Eigen::Vector3d::Zero());
}

SyntheticOptions Sequence(int width, int height) {
  SyntheticOptions o;
  o.width = width;
  o.height = height;
  return o;
}

TEST(OdometryPyramidTest, LevelsHalveTheIntrinsicsExactlyAndStartAtMaxWidth) {
  const PinholeIntrinsics k = SyntheticCamera(640, 480);
  const OdometryPyramid p = Pyramid(RenderSyntheticView(SE3::Identity(), k), k);
  ASSERT_EQ(p.levels.size(), 4u);  // 320, 160, 80, 40 (the next would be below min_width)
  EXPECT_EQ(p.levels[0].width, 320);
  EXPECT_EQ(p.levels[3].width, 40);
  EXPECT_EQ(p.levels[1].fx, static_cast<float>(k.fx / 4));
  EXPECT_EQ(p.levels[1].cx, static_cast<float>(k.cx / 4));
  EXPECT_GT(p.valid_depth, 320 * 240 * 9 / 10);
}

TEST(OdometryPyramidTest, ABlockAcrossAnEdgeKeepsTheForegroundDepth) {
  PinholeIntrinsics k{100, 100, 8, 8, 16, 16};
  RgbdFrame f;
  f.color = ColorImage(16, 16, 3, 0.5f);
  f.depth = DepthImage(16, 16, 1, 3.0f);
  f.depth.pixel(0, 0)[0] = 1.0f;  // two foreground pixels in the first 2x2 block
  f.depth.pixel(1, 0)[0] = 1.02f;
  OdometryPyramidOptions o;
  o.max_width = 8;
  o.min_width = 8;
  absl::StatusOr<OdometryPyramid> p = BuildOdometryPyramid(f, k, o);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_FLOAT_EQ(p->levels[0].depth[0], 1.01f);  // not (1 + 1.02 + 3 + 3) / 4
  EXPECT_FLOAT_EQ(p->levels[0].depth[1], 3.0f);
}

TEST(OdometryPyramidTest, ImagesThatDoNotMatchTheIntrinsicsAreInvalidArgument) {
  const PinholeIntrinsics k = SyntheticCamera(64, 48);
  RgbdFrame f = RenderSyntheticView(SE3::Identity(), SyntheticCamera(80, 60));
  EXPECT_TRUE(absl::IsInvalidArgument(
      BuildOdometryPyramid(f, k, OdometryPyramidOptions()).status()));
}

TEST(RgbdOdometryTest, ConsecutiveFramesMatchTheGroundTruth) {
  const SyntheticOptions s = Sequence(320, 240);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  for (int i : {0, 17, 40}) {
    const SE3 a = SyntheticCameraPose(s, i), b = SyntheticCameraPose(s, i + 1);
    const OdometryResult r = Align(a, b, k);
    EXPECT_TRUE(r.ok) << r.reason;
    const PoseError e = ErrorOf(r.reference_T_current, a.Inverse() * b);
    // Noise-free views: the residual error is interpolation, well under a millimetre.
    EXPECT_LT(e.translation_m, 0.001) << "frame " << i;
    EXPECT_LT(e.rotation_deg, 0.05) << "frame " << i;
    EXPECT_GT(r.valid_fraction, 0.9);
    EXPECT_GT(r.depth_inlier_fraction, 0.9);
  }
}

TEST(RgbdOdometryTest, FourTimesTheMotionPerFrameFromTheIdentity) {
  const SyntheticOptions s = Sequence(320, 240);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  const SE3 a = SyntheticCameraPose(s, 10), b = SyntheticCameraPose(s, 14);
  const OdometryResult r = Align(a, b, k);
  EXPECT_TRUE(r.ok) << r.reason;
  const PoseError e = ErrorOf(r.reference_T_current, a.Inverse() * b);
  EXPECT_LT(e.translation_m, 0.002);
  EXPECT_LT(e.rotation_deg, 0.1);
}

// A headset turning at 150 deg/s and walking 1.5 m/s: 5 degrees and 5 cm between 30 fps frames,
// at 640x480 (the odometry works at 320x240 and coarser).
TEST(RgbdOdometryTest, AFastHeadTurnConvergesFromTheIdentity) {
  const SyntheticOptions s = Sequence(640, 480);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  const SE3 a = SyntheticCameraPose(s, 25);
  const SE3 motion = Yaw(5.0) * SE3(Eigen::Quaterniond::Identity(), {0.03, 0.0, 0.04});
  const OdometryResult r = Align(a, a * motion, k);
  EXPECT_TRUE(r.ok) << r.reason;
  const PoseError e = ErrorOf(r.reference_T_current, motion);
  EXPECT_LT(e.translation_m, 0.002);
  EXPECT_LT(e.rotation_deg, 0.1);
}

TEST(RgbdOdometryTest, ColourShiftedAgainstDepthStillGivesTheMotion) {
  const SyntheticOptions s = Sequence(320, 240);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  const SE3 a = SyntheticCameraPose(s, 30), b = SyntheticCameraPose(s, 32);
  // An unregistered sensor: colour 3 px right and 2 px down of its depth, in both frames.
  auto shifted = [&](const SE3& pose) {
    RgbdFrame f = RenderSyntheticView(pose, k);
    ColorImage moved(f.color.width, f.color.height, 3, 0.0f);
    for (int v = 0; v < f.color.height; ++v) {
      for (int u = 0; u < f.color.width; ++u) {
        const int su = std::min(f.color.width - 1, std::max(0, u - 3));
        const int sv = std::min(f.color.height - 1, std::max(0, v - 2));
        for (int c = 0; c < 3; ++c) moved.pixel(u, v)[c] = f.color.pixel(su, sv)[c];
      }
    }
    f.color = std::move(moved);
    return f;
  };
  absl::StatusOr<OdometryResult> r = EstimateOdometry(
      Pyramid(shifted(a), k), Pyramid(shifted(b), k), SE3::Identity(), OdometryOptions());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->ok) << r->reason;
  const PoseError e = ErrorOf(r->reference_T_current, a.Inverse() * b);
  EXPECT_LT(e.translation_m, 0.005);
  EXPECT_LT(e.rotation_deg, 0.3);
}

TEST(RgbdOdometryTest, SensorNoiseAndHolesCostMillimetres) {
  SyntheticOptions s = Sequence(320, 240);
  s.num_frames = 3;
  s.depth_noise = 0.004;
  s.hole_fraction = 0.1;
  absl::StatusOr<InMemoryDataset> seq = GenerateSyntheticSequence(s);
  ASSERT_TRUE(seq.ok()) << seq.status();
  const PinholeIntrinsics k = seq->calibration().pinhole;
  const RgbdFrame& a = seq->frames()[0];
  const RgbdFrame& b = seq->frames()[2];
  absl::StatusOr<OdometryResult> r =
      EstimateOdometry(Pyramid(a, k), Pyramid(b, k), SE3::Identity(), OdometryOptions());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->ok) << r->reason;
  const PoseError e = ErrorOf(r->reference_T_current, a.ground_truth->Inverse() * *b.ground_truth);
  EXPECT_LT(e.translation_m, 0.005);
  EXPECT_LT(e.rotation_deg, 0.2);
}

TEST(RgbdOdometryTest, ACoveredLensIsNotOk) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  const RgbdFrame a = RenderSyntheticView(SyntheticCameraPose(Sequence(320, 240), 5), k);
  RgbdFrame covered;
  covered.color = ColorImage(k.width, k.height, 3, 0.02f);
  covered.depth = DepthImage(k.width, k.height, 1, 0.0f);
  absl::StatusOr<OdometryResult> r =
      EstimateOdometry(Pyramid(a, k), Pyramid(covered, k), SE3::Identity(), OdometryOptions());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_FALSE(r->ok);
  EXPECT_NE(r->reason.find("too little depth"), std::string::npos) << r->reason;
}

TEST(RgbdOdometryTest, AViewOfSomewhereElseIsNotOk) {
  // The reference looks at one wall, the current frame at the opposite one: nothing of the
  // current frame is where the reference saw it.
  const SyntheticOptions s = Sequence(160, 120);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  const SE3 a = SyntheticCameraPose(s, 0);
  const OdometryResult r = Align(a, a * Yaw(180.0), k);
  EXPECT_FALSE(r.ok);
}

TEST(RgbdOdometryTest, TheSameInputGivesTheSameBits) {
  const SyntheticOptions s = Sequence(320, 240);
  const PinholeIntrinsics k = SyntheticCalibration(s).pinhole;
  const SE3 a = SyntheticCameraPose(s, 3), b = SyntheticCameraPose(s, 5);
  const OdometryResult r1 = Align(a, b, k), r2 = Align(a, b, k);
  EXPECT_EQ(r1.reference_T_current.matrix(), r2.reference_T_current.matrix());
  EXPECT_EQ(r1.iterations, r2.iterations);
}

TEST(RgbdOdometryTest, PyramidsOfDifferentCamerasAreInvalidArgument) {
  const PinholeIntrinsics k1 = SyntheticCamera(320, 240), k2 = SyntheticCamera(160, 120);
  const OdometryPyramid a = Pyramid(RenderSyntheticView(SE3::Identity(), k1), k1);
  const OdometryPyramid b = Pyramid(RenderSyntheticView(SE3::Identity(), k2), k2);
  EXPECT_TRUE(absl::IsInvalidArgument(
      EstimateOdometry(a, b, SE3::Identity(), OdometryOptions()).status()));
}

}  // namespace
}  // namespace plx

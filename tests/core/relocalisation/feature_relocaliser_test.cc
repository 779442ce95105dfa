#include "core/relocalisation/feature_relocaliser.h"

#include <cmath>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/relocalisation/frame_features.h"
#include "core/synthetic/synthetic_path.h"
#include "core/synthetic/synthetic_scene.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

using ::plx::testing::SyntheticCamera;

FrameFeatures FeaturesAt(const SE3& pose, const PinholeIntrinsics& k) {
  absl::StatusOr<FrameFeatures> f =
      ExtractFrameFeatures(RenderSyntheticView(pose, k), k, FrameFeatureOptions());
  EXPECT_TRUE(f.ok()) << f.status();
  return *std::move(f);
}

// Keyframes every 1.5 s around the synthetic circle (one turn in 12 s): eight places, each
// about 45 degrees of heading from the next.
struct Keyframes {
  std::vector<SE3> poses;
  std::vector<FrameFeatures> features;
  std::vector<RelocalisationKeyframe> view() const {
    std::vector<RelocalisationKeyframe> out;
    for (size_t i = 0; i < poses.size(); ++i) out.push_back({&features[i], poses[i]});
    return out;
  }
};

Keyframes AroundTheRoom(const PinholeIntrinsics& k) {
  Keyframes out;
  for (int i = 0; i < 8; ++i) {
    out.poses.push_back(SyntheticCameraPoseAtTime(1.5 * i));
    out.features.push_back(FeaturesAt(out.poses.back(), k));
  }
  return out;
}

double TranslationError(const SE3& a, const SE3& b) {
  return (a.translation() - b.translation()).norm();
}
double RotationErrorDeg(const SE3& a, const SE3& b) {
  return RotationAngleBetween(a, b) * 180.0 / M_PI;
}

TEST(FrameFeaturesTest, KeypointsHaveDepthAndBackProjectOntoTheirPixels) {
  const PinholeIntrinsics k = SyntheticCamera(640, 480);
  const FrameFeatures f = FeaturesAt(SyntheticCameraPoseAtTime(0.0), k);
  // The room's procedural texture gives hundreds of corners; 500 are asked for.
  EXPECT_GE(f.size(), 150);
  EXPECT_LE(f.size(), FrameFeatureOptions().max_features);
  ASSERT_EQ(f.pixels.size(), f.points.size());
  ASSERT_EQ(f.descriptors.size(), f.points.size());
  for (int i = 0; i < f.size(); ++i) {
    const Eigen::Vector3f& p = f.points[i];
    ASSERT_GT(p.z(), 0.1f);
    // The pinhole model with our pixel-centre convention, in float.
    EXPECT_NEAR(k.fx * p.x() / p.z() + k.cx, f.pixels[i].x(), 1e-3);
    EXPECT_NEAR(k.fy * p.y() / p.z() + k.cy, f.pixels[i].y(), 1e-3);
  }
  EXPECT_EQ(f.thumbnail_width, 40);
  EXPECT_EQ(f.thumbnail_height, 30);
  EXPECT_NEAR(ThumbnailSimilarity(f, f), 1.0f, 1e-4f);
}

TEST(FrameFeaturesTest, ACoveredLensOrNoDepthGivesNoKeypoints) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  RgbdFrame covered;
  covered.color = ColorImage(320, 240, 3, 0.02f);
  covered.depth = DepthImage(320, 240, 1, 0.0f);
  absl::StatusOr<FrameFeatures> f = ExtractFrameFeatures(covered, k, FrameFeatureOptions());
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->size(), 0);
  // A flat thumbnail is similar to nothing, itself included.
  EXPECT_EQ(ThumbnailSimilarity(*f, *f), 0.0f);

  RgbdFrame no_depth = RenderSyntheticView(SyntheticCameraPoseAtTime(0.0), k);
  for (float& d : no_depth.depth.data) d = 0.0f;
  f = ExtractFrameFeatures(no_depth, k, FrameFeatureOptions());
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->size(), 0);
}

TEST(FrameFeaturesTest, MismatchedIntrinsicsAndBadOptionsAreRefused) {
  const RgbdFrame frame = RenderSyntheticView(SE3(), SyntheticCamera(64, 48));
  EXPECT_EQ(
      ExtractFrameFeatures(frame, SyntheticCamera(80, 60), FrameFeatureOptions()).status().code(),
      absl::StatusCode::kInvalidArgument);
  FrameFeatureOptions o;
  o.max_features = 0;
  EXPECT_FALSE(ValidateFrameFeatureOptions(o).ok());
  o = FrameFeatureOptions();
  o.max_depth = o.min_depth;
  EXPECT_FALSE(ValidateFrameFeatureOptions(o).ok());
  EXPECT_TRUE(ValidateFrameFeatureOptions(FrameFeatureOptions()).ok());
  FeatureRelocaliserOptions r;
  r.min_inliers = 30;  // more than min_matches
  EXPECT_FALSE(ValidateFeatureRelocaliserOptions(r).ok());
  EXPECT_TRUE(ValidateFeatureRelocaliserOptions(FeatureRelocaliserOptions()).ok());
}

TEST(FeatureRelocaliserTest, TheNearestPlaceRanksFirst) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  const Keyframes keyframes = AroundTheRoom(k);
  // 0.2 s after keyframe 3's time: ~6 degrees and a few centimetres from it.
  const FrameFeatures query = FeaturesAt(SyntheticCameraPoseAtTime(4.7), k);
  const std::vector<int> ranked = RankKeyframes(query, keyframes.view(), 3);
  ASSERT_FALSE(ranked.empty());
  EXPECT_EQ(ranked[0], 3);
}

TEST(FeatureRelocaliserTest, AKidnappedFrameFindsItsPoseFromTheKeyframesAlone) {
  const PinholeIntrinsics k = SyntheticCamera(640, 480);
  const Keyframes keyframes = AroundTheRoom(k);
  // Between keyframes, anywhere on the circle: no prior, no motion model, only the keyframes.
  for (double t : {0.7, 4.0, 8.2, 11.0}) {
    const SE3 truth = SyntheticCameraPoseAtTime(t);
    const FrameFeatures query = FeaturesAt(truth, k);
    const std::optional<FeatureRelocalisation> found =
        RelocaliseByFeatures(query, keyframes.view(), k, FeatureRelocaliserOptions());
    ASSERT_TRUE(found.has_value()) << "t = " << t;
    // Exact synthetic depth and sub-pixel keypoints: a few millimetres; the bound leaves room
    // for ORB's quantised keypoint positions at its coarser scales.
    EXPECT_LT(TranslationError(found->pose, truth), 0.02) << "t = " << t;
    EXPECT_LT(RotationErrorDeg(found->pose, truth), 1.0) << "t = " << t;
    EXPECT_GE(found->inliers, FeatureRelocaliserOptions().min_inliers);
    EXPECT_LE(found->inliers, found->matches);
    // The keyframe it used is one of the two it lies between.
    const int before = static_cast<int>(t / 1.5);
    EXPECT_TRUE(found->keyframe == before || found->keyframe == (before + 1) % 8)
        << "t = " << t << ": keyframe " << found->keyframe;
  }
}

TEST(FeatureRelocaliserTest, NoPoseForAFrameThatSeesNothingKnown) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  const Keyframes keyframes = AroundTheRoom(k);
  RgbdFrame covered;
  covered.color = ColorImage(320, 240, 3, 0.02f);
  covered.depth = DepthImage(320, 240, 1, 0.0f);
  absl::StatusOr<FrameFeatures> f = ExtractFrameFeatures(covered, k, FrameFeatureOptions());
  ASSERT_TRUE(f.ok());
  EXPECT_FALSE(RelocaliseByFeatures(*f, keyframes.view(), k, FeatureRelocaliserOptions()));
  // No keyframes at all.
  EXPECT_FALSE(RelocaliseByFeatures(keyframes.features[0], {}, k, FeatureRelocaliserOptions()));
}

TEST(FeatureRelocaliserTest, MatchesAreMutualAndPassTheRatioTest) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  const FrameFeatures a = FeaturesAt(SyntheticCameraPoseAtTime(0.0), k);
  const FrameFeatures b = FeaturesAt(SyntheticCameraPoseAtTime(0.2), k);
  const auto matches = MatchFeatures(a, b, FeatureRelocaliserOptions());
  ASSERT_GE(matches.size(), 30u);
  std::vector<int> used(b.size(), 0);
  for (const auto& [i, j] : matches) {
    ASSERT_GE(i, 0);
    ASSERT_LT(i, a.size());
    ASSERT_GE(j, 0);
    ASSERT_LT(j, b.size());
    EXPECT_EQ(++used[j], 1) << "keyframe point " << j << " matched twice";
  }
  // A stricter ratio keeps fewer.
  FeatureRelocaliserOptions strict;
  strict.ratio = 0.5f;
  EXPECT_LT(MatchFeatures(a, b, strict).size(), matches.size());
}

TEST(FeatureRelocaliserTest, TheSameInputsGiveTheSamePoseOnAnyThread) {
  const PinholeIntrinsics k = SyntheticCamera(320, 240);
  const Keyframes keyframes = AroundTheRoom(k);
  const FrameFeatures query = FeaturesAt(SyntheticCameraPoseAtTime(5.2), k);
  const std::optional<FeatureRelocalisation> here =
      RelocaliseByFeatures(query, keyframes.view(), k, FeatureRelocaliserOptions());
  ASSERT_TRUE(here.has_value());
  std::optional<FeatureRelocalisation> there;
  std::thread other([&] {
    // This thread's OpenCV generator is in another state: RANSAC must not depend on it.
    for (int i = 0; i < 17; ++i) cv::theRNG().next();
    there = RelocaliseByFeatures(query, keyframes.view(), k, FeatureRelocaliserOptions());
  });
  other.join();
  for (int i = 0; i < 5; ++i) cv::theRNG().next();
  const std::optional<FeatureRelocalisation> again =
      RelocaliseByFeatures(query, keyframes.view(), k, FeatureRelocaliserOptions());
  for (const auto& r : {there, again}) {
    ASSERT_TRUE(r.has_value());
    EXPECT_EQ(r->keyframe, here->keyframe);
    EXPECT_EQ(r->inliers, here->inliers);
    EXPECT_EQ(r->pose.translation(), here->pose.translation());
    EXPECT_EQ(r->pose.rotation().coeffs(), here->pose.rotation().coeffs());
  }
}

}  // namespace
}  // namespace plx

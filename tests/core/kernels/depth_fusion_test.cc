#include "core/kernels/depth_fusion.h"

#include <vector>

#include <gtest/gtest.h>

#include "core/geometry/kernel_camera.h"
#include "core/geometry/se3.h"

namespace plx {
namespace {

// One keyframe at the origin looking at a uniformly coloured wall 2 m away.
class DepthFusionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    k_ = PinholeIntrinsics{50, 50, 20, 15, 40, 30};
    depth_.assign(40 * 30, 2.0f);
    color_.assign(40 * 30 * 3, 0.0f);
    for (size_t i = 0; i < color_.size(); i += 3) {
      color_[i] = 0.9f;
      color_[i + 1] = 0.4f;
      color_[i + 2] = 0.1f;
    }
    frame_.camera = ToKernelCamera(SE3(), k_);
    frame_.color = color_.data();
    frame_.depth = depth_.data();
    params_.min_truncation = 0.08f;
    params_.truncation_sigmas = 0.0f;
    params_.ramp = 0.02f;
    params_.sigma_max = 100.0f;
    params_.color_band = 0.03f;
    params_.noise = DepthNoiseModel{0.0f, 0.0f, 0.0f};
  }
  VertexFusion At(float z) const { return FuseVertex(Vec3f{0.01f, 0.02f, z}, &frame_, 1, params_); }

  PinholeIntrinsics k_;
  std::vector<float> depth_, color_;
  TrainingFrameView frame_;
  FusionParams params_;
};

TEST_F(DepthFusionTest, DensityStepsUpAtTheSurface) {
  EXPECT_FLOAT_EQ(At(1.5f).density, 0.0f);    // free space in front
  EXPECT_FLOAT_EQ(At(1.98f).density, 0.0f);   // 2 cm in front: end of the ramp
  EXPECT_NEAR(At(2.0f).density, 50.0f, 1e-3); // at the surface: half way
  EXPECT_FLOAT_EQ(At(2.05f).density, 100.0f); // behind
  EXPECT_TRUE(At(1.5f).observed);
  EXPECT_FALSE(At(2.5f).observed);  // hidden behind the surface beyond the truncation
  EXPECT_FLOAT_EQ(At(2.5f).density, 0.0f);
}

TEST_F(DepthFusionTest, ColourComesFromObservationsNearTheSurface) {
  const VertexFusion near = At(2.01f);
  ASSERT_TRUE(near.color_observed);
  EXPECT_FLOAT_EQ(near.color[0], 0.9f);
  EXPECT_FLOAT_EQ(near.color[2], 0.1f);
  const VertexFusion far = At(1.7f);
  EXPECT_FALSE(far.color_observed);
  EXPECT_FLOAT_EQ(far.color[1], 0.5f);  // unobserved colour is neutral grey
}

TEST_F(DepthFusionTest, InvalidDepthAndPointsOutsideTheImageAreUnobserved) {
  std::fill(depth_.begin(), depth_.end(), 0.0f);
  EXPECT_FALSE(At(2.0f).observed);
  EXPECT_FALSE(FuseVertex(Vec3f{5.0f, 0.0f, 2.0f}, &frame_, 1, params_).observed);
  EXPECT_FALSE(FuseVertex(Vec3f{0.0f, 0.0f, -1.0f}, &frame_, 1, params_).observed);
}

TEST_F(DepthFusionTest, TruncationWidensWithSensorNoise) {
  params_.noise = DepthNoiseModel{0.0f, 0.05f, 0.0f};  // sigma(2 m) = 0.2 m
  params_.truncation_sigmas = 1.0f;
  EXPECT_TRUE(At(2.15f).observed);  // within the noise-wide truncation now
}

}  // namespace
}  // namespace plx

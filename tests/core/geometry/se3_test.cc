#include "core/geometry/se3.h"

#include <random>

#include <gtest/gtest.h>

namespace plx {
namespace {

Vector6d RandomTangent(std::mt19937& rng, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  Vector6d xi;
  for (int i = 0; i < 6; ++i) xi[i] = n(rng);
  return xi;
}

TEST(SE3Test, ExpLogRoundTrip) {
  std::mt19937 rng(51);
  for (int i = 0; i < 100; ++i) {
    Vector6d xi = RandomTangent(rng, i < 50 ? 1.0 : 1e-7);
    // Log returns rotation angles in [0, pi]; keep the sample inside that chart.
    if (xi.tail<3>().norm() > 3.0) xi.tail<3>() *= 3.0 / xi.tail<3>().norm();
    const Vector6d back = SE3::Exp(xi).Log();
    EXPECT_LT((back - xi).norm(), 1e-9 * std::max(1.0, xi.norm())) << xi.transpose();
  }
}

TEST(SE3Test, ExpMatchesTheMatrixExponential) {
  // exp of the 4x4 twist matrix via a long Taylor series, for a moderate twist.
  Vector6d xi;
  xi << 0.3, -0.2, 0.5, 0.4, -0.1, 0.25;
  Eigen::Matrix4d twist = Eigen::Matrix4d::Zero();
  twist.topLeftCorner<3, 3>() = Hat(xi.tail<3>());
  twist.topRightCorner<3, 1>() = xi.head<3>();
  Eigen::Matrix4d sum = Eigen::Matrix4d::Identity(), term = Eigen::Matrix4d::Identity();
  for (int k = 1; k < 30; ++k) {
    term = term * twist / k;
    sum += term;
  }
  EXPECT_LT((SE3::Exp(xi).matrix() - sum).norm(), 1e-12);
}

TEST(SE3Test, CompositionInverseAndPoints) {
  std::mt19937 rng(52);
  const SE3 a = SE3::Exp(RandomTangent(rng, 1.0)), b = SE3::Exp(RandomTangent(rng, 1.0));
  const Eigen::Vector3d p(0.3, -1.2, 2.0);
  EXPECT_LT(((a * b) * p - a * (b * p)).norm(), 1e-12);
  EXPECT_LT(((a * a.Inverse()).matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-12);
  EXPECT_LT(((a * b).matrix() - a.matrix() * b.matrix()).norm(), 1e-12);
  Vector6d turn = Vector6d::Zero();
  turn[5] = 0.3;
  EXPECT_NEAR(RotationAngleBetween(a, a * SE3::Exp(turn)), 0.3, 1e-12);
  EXPECT_TRUE(a.IsFinite());
}

}  // namespace
}  // namespace plx

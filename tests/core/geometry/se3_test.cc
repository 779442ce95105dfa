#include "core/geometry/se3.h"

#include <limits>
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

// Found by fuzz_text_files and fuzz_frame_proto: Eigen's normalized() squares the components,
// so a quaternion of 1e200s became a zero rotation instead of a unit one.
TEST(SE3Test, UnitQuaternionNormalisesHugeAndTinyComponents) {
  for (const double scale : {1.0, 1e200, 1e-200, 1.7e308, 4.9e-324}) {
    SCOPED_TRACE(scale);
    const std::optional<Eigen::Quaterniond> q =
        UnitQuaternion(Eigen::Quaterniond(scale, scale, 0.0, 0.0), /*min_norm=*/0.0);
    ASSERT_TRUE(q.has_value());
    EXPECT_NEAR(q->norm(), 1.0, 1e-15);
    EXPECT_NEAR(q->w(), std::sqrt(0.5), 1e-15);
    EXPECT_NEAR(q->x(), std::sqrt(0.5), 1e-15);
  }
}

TEST(SE3Test, UnitQuaternionMatchesNormalizedBitForBitInRange) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 3.0);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
    const std::optional<Eigen::Quaterniond> unit = UnitQuaternion(q, 1e-6);
    ASSERT_TRUE(unit.has_value());
    EXPECT_EQ(unit->coeffs(), q.normalized().coeffs());
  }
}

TEST(SE3Test, UnitQuaternionRefusesZeroShortAndNonFinite) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(UnitQuaternion(Eigen::Quaterniond(0, 0, 0, 0), 1e-6).has_value());
  EXPECT_FALSE(UnitQuaternion(Eigen::Quaterniond(1e-7, 0, 0, 0), 1e-6).has_value());
  EXPECT_FALSE(UnitQuaternion(Eigen::Quaterniond(1e-200, 0, 0, 0), 1e-6).has_value());
  EXPECT_FALSE(UnitQuaternion(Eigen::Quaterniond(inf, 0, 0, 0), 1e-6).has_value());
  EXPECT_FALSE(
      UnitQuaternion(Eigen::Quaterniond(1, std::nan(""), 0, 0), 1e-6).has_value());
  EXPECT_TRUE(UnitQuaternion(Eigen::Quaterniond(2e-6, 0, 0, 0), 1e-6).has_value());
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

// Trajectory metrics on trajectories whose errors can be worked out by hand. Suite names start
// with Trajectory, Ate, Rpe or Umeyama so one gtest filter selects them all.
#include "core/eval/trajectory_metrics.h"

#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;

constexpr double kDegToRad = M_PI / 180.0;

SE3 Translation(double x, double y, double z) {
  return SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, y, z));
}

SE3 RotationZ(double radians) {
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(radians, Eigen::Vector3d::UnitZ())),
             Eigen::Vector3d::Zero());
}

Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  return Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized();
}

// A helix: radius 1 m around z, climbing 0.2 m per turn, one pose every 0.05 rad (about 5 cm),
// the camera turning with the path. `n` poses, stamps 0.1 s apart from t0.
std::vector<StampedPose> Helix(int n, double t0 = 100.0) {
  std::vector<StampedPose> poses;
  for (int k = 0; k < n; ++k) {
    const double a = 0.05 * k;
    const SE3 pose(Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) *
                                      Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX())),
                   Eigen::Vector3d(std::cos(a), std::sin(a), 0.2 * a / (2 * M_PI)));
    poses.push_back({t0 + 0.1 * k, pose});
  }
  return poses;
}

std::vector<SE3> Poses(const std::vector<StampedPose>& stamped) {
  std::vector<SE3> poses;
  for (const StampedPose& p : stamped) poses.push_back(p.pose);
  return poses;
}

// A straight line along x at 1 m/s sampled at 8 Hz: 0.125 m steps, exact in binary, so path
// sums hit 1 m exactly. Poses k = 0 .. n-1.
std::vector<SE3> StraightLine(int n, double step = 0.125) {
  std::vector<SE3> poses;
  for (int k = 0; k < n; ++k) poses.push_back(Translation(step * k, 0.0, 0.0));
  return poses;
}

double RotationDistance(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return (a - b).norm();
}

// ---------------------------------------------------------------------------------------------
// Statistics

TEST(TrajectoryErrorStatisticsTest, MatchesNumpyDefinitions) {
  const ErrorStatistics even = ComputeErrorStatistics({4.0, 1.0, 3.0, 2.0});
  EXPECT_EQ(even.count, 4);
  EXPECT_DOUBLE_EQ(even.rmse, std::sqrt(30.0 / 4.0));
  EXPECT_DOUBLE_EQ(even.mean, 2.5);
  EXPECT_DOUBLE_EQ(even.median, 2.5);         // mean of the two middle values
  EXPECT_DOUBLE_EQ(even.std, std::sqrt(1.25));  // population std (ddof = 0)
  EXPECT_DOUBLE_EQ(even.min, 1.0);
  EXPECT_DOUBLE_EQ(even.max, 4.0);
  EXPECT_DOUBLE_EQ(ComputeErrorStatistics({5.0, 1.0, 2.0}).median, 2.0);

  const ErrorStatistics none = ComputeErrorStatistics({});
  EXPECT_EQ(none.count, 0);
  EXPECT_TRUE(std::isnan(none.rmse));
  EXPECT_TRUE(std::isnan(none.median));
}

TEST(TrajectoryOptionsTest, ParsesNames) {
  EXPECT_EQ(*ParseTrajectoryAlignment("none"), TrajectoryAlignment::kNone);
  EXPECT_EQ(*ParseTrajectoryAlignment("se3"), TrajectoryAlignment::kSE3);
  EXPECT_EQ(*ParseTrajectoryAlignment("sim3"), TrajectoryAlignment::kSim3);
  EXPECT_FALSE(ParseTrajectoryAlignment("SE3x").ok());
  for (TrajectoryAlignment a :
       {TrajectoryAlignment::kNone, TrajectoryAlignment::kSE3, TrajectoryAlignment::kSim3}) {
    EXPECT_EQ(*ParseTrajectoryAlignment(TrajectoryAlignmentName(a)), a);
  }
  EXPECT_EQ(*ParseRpePathSource("est"), RpePathSource::kEstimate);
  EXPECT_EQ(*ParseRpePathSource("gt"), RpePathSource::kGroundTruth);
  EXPECT_FALSE(ParseRpePathSource("ref").ok());
}

TEST(TrajectoryRotationAngleTest, AccurateForSmallAndLargeAngles) {
  EXPECT_NEAR(RotationAngle(RotationZ(1e-9)), 1e-9, 1e-20);
  EXPECT_NEAR(RotationAngle(RotationZ(2.0)), 2.0, 1e-14);
  EXPECT_NEAR(RotationAngle(RotationZ(-2.0)), 2.0, 1e-14);
  EXPECT_NEAR(RotationAngle(RotationZ(M_PI)), M_PI, 1e-14);
}

// ---------------------------------------------------------------------------------------------
// Association

TEST(TrajectoryAssociationTest, NearestGroundTruthWithinMaxDt) {
  // Ground truth at 100 Hz over [0, 2) s with a gap (no samples in (1.0, 1.2)); the estimate at
  // 25 Hz with up to +-4 ms of jitter.
  std::vector<double> gt;
  for (int k = 0; k < 200; ++k) {
    const double t = 0.01 * k;
    if (t > 1.0 + 1e-9 && t < 1.2 - 1e-9) continue;
    gt.push_back(t);
  }
  const double jitter[] = {0.0, 0.004, -0.003, 0.002, -0.004};
  std::vector<double> est;
  for (int k = 0; k < 50; ++k) est.push_back(0.04 * k + jitter[k % 5]);

  const auto pairs = AssociateEstimateToGroundTruth(est, gt, 0.02);
  std::vector<int> expected_unmatched;
  int next = 0;
  for (int k = 0; k < 50; ++k) {
    // The nearest gt stamp by brute force.
    int best = 0;
    for (int g = 1; g < static_cast<int>(gt.size()); ++g) {
      if (std::abs(gt[g] - est[k]) < std::abs(gt[best] - est[k])) best = g;
    }
    if (std::abs(gt[best] - est[k]) > 0.02) {
      expected_unmatched.push_back(k);
      continue;
    }
    ASSERT_LT(next, static_cast<int>(pairs.size()));
    EXPECT_EQ(pairs[next], std::make_pair(k, best)) << "estimate " << k;
    ++next;
  }
  EXPECT_EQ(next, static_cast<int>(pairs.size()));
  // Stamps 1.04 .. 1.16 (k = 26..29; 1.04 + 0.004 etc.) are more than 20 ms from any sample.
  EXPECT_THAT(expected_unmatched, ElementsAre(26, 27, 28, 29));
}

TEST(TrajectoryAssociationTest, EachGroundTruthPoseUsedOnce) {
  // Estimates 0.9 and 1.05 both have 1.0 as their nearest; 1.05 is closer and keeps it.
  const std::vector<double> gt = {1.0, 2.0};
  EXPECT_THAT(AssociateEstimateToGroundTruth({0.9, 1.05, 2.0}, gt, 0.2),
              ElementsAre(Pair(1, 0), Pair(2, 1)));
  // Equally close: the earlier estimate keeps it.
  EXPECT_THAT(AssociateEstimateToGroundTruth({0.875, 1.125}, gt, 0.2), ElementsAre(Pair(0, 0)));
}

TEST(TrajectoryAssociationTest, TiesBoundaryAndUnsortedInput) {
  // Exactly between 1.0 and 1.5: the earlier stamp wins (numpy argmin takes the first).
  EXPECT_THAT(AssociateEstimateToGroundTruth({1.25}, {1.0, 1.5}, 0.25), ElementsAre(Pair(0, 0)));
  // |dt| == max_dt is accepted (values exact in binary), just above is not.
  EXPECT_THAT(AssociateEstimateToGroundTruth({1.25}, {1.5}, 0.25), ElementsAre(Pair(0, 0)));
  EXPECT_TRUE(AssociateEstimateToGroundTruth({1.25}, {1.5}, 0.2499).empty());
  // Unsorted inputs; indices refer to the inputs as given.
  EXPECT_THAT(AssociateEstimateToGroundTruth({3.0, 1.0, 2.0}, {2.01, 0.99, 3.02}, 0.05),
              ElementsAre(Pair(0, 2), Pair(1, 1), Pair(2, 0)));
  EXPECT_TRUE(AssociateEstimateToGroundTruth({1.0}, {}, 1.0).empty());
  EXPECT_TRUE(AssociateEstimateToGroundTruth({}, {1.0}, 1.0).empty());
}

// ---------------------------------------------------------------------------------------------
// Umeyama

TEST(UmeyamaTest, RecoversRandomSimilarityAndRigidTransform) {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> uniform(-2.0, 2.0);
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Matrix3Xd source(3, 30);
    for (int i = 0; i < source.cols(); ++i) {
      source.col(i) = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    }
    const Eigen::Matrix3d rotation = RandomRotation(rng).toRotationMatrix();
    const Eigen::Vector3d translation(uniform(rng), uniform(rng), uniform(rng));
    const double scale = 0.2 + std::abs(uniform(rng));

    const Eigen::Matrix3Xd rigid_target = (rotation * source).colwise() + translation;
    absl::StatusOr<Similarity3> se3 = UmeyamaAlignment(source, rigid_target, false);
    ASSERT_TRUE(se3.ok()) << se3.status();
    EXPECT_LT(RotationDistance(se3->rotation, rotation), 1e-9);
    EXPECT_LT((se3->translation - translation).norm(), 1e-9);
    EXPECT_EQ(se3->scale, 1.0);

    const Eigen::Matrix3Xd similar_target = (scale * rotation * source).colwise() + translation;
    absl::StatusOr<Similarity3> sim3 = UmeyamaAlignment(source, similar_target, true);
    ASSERT_TRUE(sim3.ok()) << sim3.status();
    EXPECT_LT(RotationDistance(sim3->rotation, rotation), 1e-9);
    EXPECT_LT((sim3->translation - translation).norm(), 1e-9);
    EXPECT_NEAR(sim3->scale, scale, 1e-9);
    EXPECT_LT(((*sim3) * Eigen::Vector3d(source.col(3)) - similar_target.col(3)).norm(), 1e-9);
  }
}

TEST(UmeyamaTest, CoplanarPointsGiveAProperRotation) {
  // All points in z = 0: the cross-covariance has rank 2 and the SVD may return a reflection;
  // the sign correction must still find the rotation.
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Matrix3Xd source(3, 12);
    for (int i = 0; i < source.cols(); ++i) {
      source.col(i) = Eigen::Vector3d(uniform(rng), uniform(rng), 0.0);
    }
    const Eigen::Matrix3d rotation = RandomRotation(rng).toRotationMatrix();
    const Eigen::Vector3d translation(0.5, -1.0, 2.0);
    const Eigen::Matrix3Xd target = (rotation * source).colwise() + translation;
    absl::StatusOr<Similarity3> a = UmeyamaAlignment(source, target, false);
    ASSERT_TRUE(a.ok()) << a.status();
    EXPECT_NEAR(a->rotation.determinant(), 1.0, 1e-12);
    EXPECT_LT(RotationDistance(a->rotation, rotation), 1e-9);
    EXPECT_LT((a->translation - translation).norm(), 1e-9);
  }
}

TEST(UmeyamaTest, MirroredPointsStillGiveARotation) {
  // target = source mirrored in z: the best orthogonal map is the mirror itself, which is not a
  // rotation. Umeyama returns the best proper rotation instead: for points spread least along z
  // that is the identity (flip the axis of the smallest singular value).
  Eigen::Matrix3Xd source(3, 6);
  source << 3, -3, 0, 0, 0, 0,  //
      0, 0, 2, -2, 0, 0,        //
      0, 0, 0, 0, 1, -1;
  const Eigen::Matrix3Xd target = Eigen::Vector3d(1, 1, -1).asDiagonal() * source;
  absl::StatusOr<Similarity3> a = UmeyamaAlignment(source, target, true);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_NEAR(a->rotation.determinant(), 1.0, 1e-12);
  EXPECT_LT(RotationDistance(a->rotation, Eigen::Matrix3d::Identity()), 1e-12);
  // tr(DS) / sigma^2 = (9 + 4 - 1) / (9 + 4 + 1) for these symmetric point pairs.
  EXPECT_NEAR(a->scale, 12.0 / 14.0, 1e-12);
}

TEST(UmeyamaTest, RejectsBadInput) {
  const Eigen::Matrix3Xd three = Eigen::Matrix3Xd::Random(3, 3);
  EXPECT_FALSE(UmeyamaAlignment(three, Eigen::Matrix3Xd::Random(3, 4), false).ok());
  EXPECT_FALSE(UmeyamaAlignment(Eigen::Matrix3Xd(3, 0), Eigen::Matrix3Xd(3, 0), false).ok());
  Eigen::Matrix3Xd with_nan = three;
  with_nan(1, 1) = std::nan("");
  EXPECT_FALSE(UmeyamaAlignment(with_nan, three, false).ok());
  // One repeated point: the rigid fit is defined (a translation), the scale is not.
  const Eigen::Matrix3Xd same = Eigen::Vector3d(1, 2, 3).replicate(1, 5);
  absl::StatusOr<Similarity3> rigid = UmeyamaAlignment(same, same.colwise() +
                                                                Eigen::Vector3d(1, 0, 0), false);
  ASSERT_TRUE(rigid.ok()) << rigid.status();
  EXPECT_LT(((*rigid) * Eigen::Vector3d(1, 2, 3) - Eigen::Vector3d(2, 2, 3)).norm(), 1e-12);
  absl::StatusOr<Similarity3> scaled = UmeyamaAlignment(same, same, true);
  ASSERT_FALSE(scaled.ok());
  EXPECT_THAT(scaled.status().message(), HasSubstr("coincide"));
}

// ---------------------------------------------------------------------------------------------
// ATE

TEST(AteTest, IdenticalTrajectoriesHaveZeroError) {
  const std::vector<SE3> poses = Poses(Helix(300));
  for (TrajectoryAlignment a :
       {TrajectoryAlignment::kNone, TrajectoryAlignment::kSE3, TrajectoryAlignment::kSim3}) {
    SCOPED_TRACE(TrajectoryAlignmentName(a));
    absl::StatusOr<AteResult> ate = ComputeAte(poses, poses, a);
    ASSERT_TRUE(ate.ok()) << ate.status();
    EXPECT_EQ(ate->translation_m.count, 300);
    EXPECT_NEAR(ate->translation_m.rmse, 0.0, 1e-12);
    EXPECT_NEAR(ate->translation_m.max, 0.0, 1e-12);
    EXPECT_NEAR(ate->alignment.scale, 1.0, 1e-12);
  }
  EXPECT_EQ(ComputeAte(poses, poses, TrajectoryAlignment::kNone)->translation_m.max, 0.0);
}

TEST(AteTest, ConstantOffsetIsTheOffsetUnalignedAndZeroAligned) {
  const std::vector<SE3> gt = Poses(Helix(300));
  std::vector<SE3> est;
  for (const SE3& p : gt) est.push_back(Translation(0.1, 0.0, 0.0) * p);

  absl::StatusOr<AteResult> none = ComputeAte(est, gt, TrajectoryAlignment::kNone);
  ASSERT_TRUE(none.ok()) << none.status();
  // Every error is 0.1 up to the rounding of (x + 0.1) - x.
  EXPECT_NEAR(none->translation_m.rmse, 0.1, 1e-15);
  EXPECT_NEAR(none->translation_m.mean, 0.1, 1e-15);
  EXPECT_NEAR(none->translation_m.median, 0.1, 1e-15);
  EXPECT_NEAR(none->translation_m.max, 0.1, 1e-15);
  EXPECT_NEAR(none->translation_m.min, 0.1, 1e-15);

  for (TrajectoryAlignment a : {TrajectoryAlignment::kSE3, TrajectoryAlignment::kSim3}) {
    absl::StatusOr<AteResult> aligned = ComputeAte(est, gt, a);
    ASSERT_TRUE(aligned.ok()) << aligned.status();
    EXPECT_NEAR(aligned->translation_m.rmse, 0.0, 1e-12);
    EXPECT_LT((aligned->alignment.translation - Eigen::Vector3d(-0.1, 0, 0)).norm(), 1e-12);
    EXPECT_NEAR(aligned->alignment.scale, 1.0, 1e-12);
  }
}

TEST(AteTest, ConstantRotationAboutTheOriginMatchesHandValue) {
  // Ground-truth camera centres (0.5, 0, 1), (1, 0, 1), (1.5, 0, 1), (2, 0, 1); the estimate is
  // the whole trajectory turned 90 degrees about the world z axis. A point at distance r from
  // the axis moves by 2 r sin(45 deg) = sqrt(2) r, so the errors are sqrt(2) * {0.5, 1, 1.5, 2}:
  //   rmse   = sqrt(2) * sqrt((0.25 + 1 + 2.25 + 4) / 4) = sqrt(3.75)
  //   mean   = sqrt(2) * 1.25, median = sqrt(2) * (1 + 1.5) / 2, max = sqrt(2) * 2.
  std::vector<SE3> gt, est;
  for (double x : {0.5, 1.0, 1.5, 2.0}) {
    const SE3 pose = Translation(x, 0.0, 1.0) * RotationZ(0.1 * x);
    gt.push_back(pose);
    est.push_back(RotationZ(M_PI / 2) * pose);
  }
  absl::StatusOr<AteResult> none = ComputeAte(est, gt, TrajectoryAlignment::kNone);
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_NEAR(none->translation_m.rmse, std::sqrt(3.75), 1e-12);
  EXPECT_NEAR(none->translation_m.mean, std::sqrt(2.0) * 1.25, 1e-12);
  EXPECT_NEAR(none->translation_m.median, std::sqrt(2.0) * 1.25, 1e-12);
  EXPECT_NEAR(none->translation_m.max, std::sqrt(2.0) * 2.0, 1e-12);

  // Collinear centres: the rotation about the line is undetermined, but the positions align.
  absl::StatusOr<AteResult> se3 = ComputeAte(est, gt, TrajectoryAlignment::kSE3);
  ASSERT_TRUE(se3.ok()) << se3.status();
  EXPECT_NEAR(se3->translation_m.rmse, 0.0, 1e-12);

  // The same with a helix (not collinear): the alignment is the inverse rotation itself.
  const std::vector<SE3> helix = Poses(Helix(200));
  std::vector<SE3> turned;
  for (const SE3& p : helix) turned.push_back(RotationZ(0.7) * p);
  se3 = ComputeAte(turned, helix, TrajectoryAlignment::kSE3);
  ASSERT_TRUE(se3.ok()) << se3.status();
  EXPECT_NEAR(se3->translation_m.rmse, 0.0, 1e-12);
  EXPECT_LT(RotationDistance(se3->alignment.rotation, RotationZ(-0.7).rotation_matrix()), 1e-12);
}

TEST(AteTest, GaussianNoiseGivesSqrt3Sigma) {
  // Each camera centre gets independent N(0, sigma^2) noise per axis, so ||error||^2 / sigma^2
  // is chi-square with 3 degrees of freedom: E[rmse^2] = 3 sigma^2, E[error] = 2 sqrt(2 / pi)
  // sigma. With n = 20000 the relative standard deviation of the sample rmse is
  // about 1 / sqrt(6 n) = 0.29 %, and that of the sample mean sqrt(3 - 8 / pi) /
  // (2 sqrt(2 / pi)) / sqrt(n) = 0.30 %; the 1.5 % tolerance is 5 of those, and the seed is fixed.
  // SE(3) alignment absorbs 6 of the 3n degrees of freedom: E[rmse^2] = sigma^2 (3n - 6) / n.
  const int n = 20000;
  const double sigma = 0.01;
  std::mt19937_64 rng(2024);
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<SE3> gt, est;
  for (int k = 0; k < n; ++k) {
    const double a = 0.001 * k;
    const SE3 pose(Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(3 * std::cos(a), 0.5 * std::sin(3 * a), 3 * std::sin(a)));
    gt.push_back(pose);
    est.push_back(SE3(pose.rotation(),
                      pose.translation() + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))));
  }
  for (TrajectoryAlignment a : {TrajectoryAlignment::kNone, TrajectoryAlignment::kSE3}) {
    SCOPED_TRACE(TrajectoryAlignmentName(a));
    absl::StatusOr<AteResult> ate = ComputeAte(est, gt, a);
    ASSERT_TRUE(ate.ok()) << ate.status();
    EXPECT_NEAR(ate->translation_m.rmse, std::sqrt(3.0) * sigma, 0.015 * std::sqrt(3.0) * sigma);
    const double expected_mean = 2.0 * std::sqrt(2.0 / M_PI) * sigma;
    EXPECT_NEAR(ate->translation_m.mean, expected_mean, 0.015 * expected_mean);
  }
}

TEST(AteTest, Sim3RecoversScale) {
  // The estimate is the ground truth at half size, turned and shifted: sim3 aligns it exactly
  // (scale 2 maps it back), se3 cannot.
  const std::vector<SE3> gt = Poses(Helix(200));
  const Similarity3 shrink{RotationZ(0.4).rotation_matrix(), Eigen::Vector3d(1, 2, 3), 0.5};
  std::vector<SE3> est;
  for (const SE3& p : gt) est.push_back(shrink * p);
  absl::StatusOr<AteResult> sim3 = ComputeAte(est, gt, TrajectoryAlignment::kSim3);
  ASSERT_TRUE(sim3.ok()) << sim3.status();
  EXPECT_NEAR(sim3->translation_m.rmse, 0.0, 1e-12);
  EXPECT_NEAR(sim3->alignment.scale, 2.0, 1e-12);
  absl::StatusOr<AteResult> se3 = ComputeAte(est, gt, TrajectoryAlignment::kSE3);
  ASSERT_TRUE(se3.ok()) << se3.status();
  EXPECT_GT(se3->translation_m.rmse, 0.1);
}

TEST(AteTest, RejectsMismatchedOrTooFewPoses) {
  const std::vector<SE3> two = {Translation(0, 0, 0), Translation(1, 0, 0)};
  EXPECT_FALSE(ComputeAte(two, {two[0]}, TrajectoryAlignment::kNone).ok());
  EXPECT_FALSE(ComputeAte({}, {}, TrajectoryAlignment::kNone).ok());
  EXPECT_TRUE(ComputeAte(two, two, TrajectoryAlignment::kNone).ok());
  absl::StatusOr<AteResult> se3 = ComputeAte(two, two, TrajectoryAlignment::kSE3);
  ASSERT_FALSE(se3.ok());
  EXPECT_THAT(se3.status().message(), HasSubstr("at least 3"));
}

// ---------------------------------------------------------------------------------------------
// RPE

TEST(RpeTest, PairsFollowEvoConsecutiveRule) {
  // Steps 0.6, 0.6 (running 1.2 >= 1: record 2, reset), 0.3, 0.5, 0.7 (1.5: record 5, reset;
  // the 0.5 overshoot is dropped, not carried), 0.05, 0.5, 0.5 (1.05: record 8), 0.15 (left
  // over). The values are chosen so no sum lands within rounding of 1.
  std::vector<SE3> poses;
  for (double x : {0.0, 0.6, 1.2, 1.5, 2.0, 2.7, 2.75, 3.25, 3.75, 3.9}) {
    poses.push_back(Translation(x, 0, 0));
  }
  EXPECT_THAT(RpePairsByPath(poses, 1.0), ElementsAre(Pair(2, 5), Pair(5, 8)));
  // The first pair starts at the first crossing, not at pose 0, so 1.9 m of path gives none.
  EXPECT_TRUE(RpePairsByPath(StraightLine(16, 0.125), 1.0).empty());  // 1.875 m
  EXPECT_THAT(RpePairsByPath(StraightLine(17, 0.125), 1.0), ElementsAre(Pair(8, 16)));
  // Standing still adds nothing.
  std::vector<SE3> pauses = StraightLine(17, 0.125);
  pauses.insert(pauses.begin() + 4, pauses[4]);
  EXPECT_THAT(RpePairsByPath(pauses, 1.0), ElementsAre(Pair(9, 17)));
  EXPECT_TRUE(RpePairsByPath({}, 1.0).empty());
  EXPECT_DOUBLE_EQ(PathLength(StraightLine(17, 0.125)), 2.0);
}

TEST(RpeTest, IdenticalAndRigidlyMovedTrajectoriesHaveZeroError) {
  const std::vector<SE3> gt = Poses(Helix(400));  // about 20 m of path
  const SE3 motion = SE3::Exp((Vector6d() << 1, -2, 3, 0.3, 0.2, -0.1).finished());
  std::vector<SE3> moved;
  for (const SE3& p : gt) moved.push_back(motion * p);
  for (const std::vector<SE3>* est : {&gt, static_cast<const std::vector<SE3>*>(&moved)}) {
    absl::StatusOr<RpeResult> rpe = ComputeRpe(*est, gt, 1.0);
    ASSERT_TRUE(rpe.ok()) << rpe.status();
    EXPECT_GE(rpe->pairs.size(), 15u);
    EXPECT_EQ(rpe->translation_m.count, static_cast<int>(rpe->pairs.size()));
    EXPECT_NEAR(rpe->translation_m.rmse, 0.0, 1e-12);
    EXPECT_NEAR(rpe->rotation_deg.rmse, 0.0, 1e-9);
  }
}

TEST(RpeTest, StraightLineWithScaleDrift) {
  // Ground truth: 1 m/s along x at 8 Hz (0.125 m per step), 81 poses = 10 m. The estimate
  // moves 1 % too far every step (0.12625 m). Either path crosses 1 m every 8 steps, so the pairs
  // are (8, 16), (16, 24), ..., (72, 80): 9 pairs, each 1.01 m estimated vs 1 m true, no
  // rotation: RPE_t = 0.01 m for every pair, RPE_r = 0.
  const std::vector<SE3> gt = StraightLine(81, 0.125);
  const std::vector<SE3> est = StraightLine(81, 0.12625);
  for (RpePathSource source : {RpePathSource::kEstimate, RpePathSource::kGroundTruth}) {
    SCOPED_TRACE(RpePathSourceName(source));
    absl::StatusOr<RpeResult> rpe = ComputeRpe(est, gt, 1.0, source);
    ASSERT_TRUE(rpe.ok()) << rpe.status();
    ASSERT_EQ(rpe->pairs.size(), 9u);
    EXPECT_EQ(rpe->pairs.front(), std::make_pair(8, 16));
    EXPECT_EQ(rpe->pairs.back(), std::make_pair(72, 80));
    EXPECT_NEAR(rpe->translation_m.rmse, 0.01, 1e-12);
    EXPECT_NEAR(rpe->translation_m.max, 0.01, 1e-12);
    EXPECT_NEAR(rpe->translation_m.min, 0.01, 1e-12);
    EXPECT_NEAR(rpe->rotation_deg.rmse, 0.0, 1e-12);
  }
  EXPECT_NEAR(ComputeRpe(est, gt, 1.0, RpePathSource::kEstimate)->path_length_m, 10.1, 1e-9);
  EXPECT_NEAR(ComputeRpe(est, gt, 1.0, RpePathSource::kGroundTruth)->path_length_m, 10.0, 1e-12);
}

TEST(RpeTest, StraightLineWithYawDrift) {
  // Ground truth steps 0.125 m forward (body x) per pose; the estimate also turns eps = 0.5 deg
  // about z each step, so est_k = (R(eps), [0.125 0 0])^k. Both travel 0.125 m per step; the
  // pairs are picked on the ground truth, whose positions are exact multiples of 0.125 (the
  // estimate's 8-step sums can round to just below 1 m), so they are (8, 16), ..., (72, 80).
  // Per pair E = (I, [1 0 0])^-1 (R(8 eps), t8) = (R(8 eps), t8 - [1 0 0]) with
  // t8 = 0.125 * sum_{k<8} [cos(k eps), sin(k eps), 0]: RPE_r = 8 eps = 4 deg for every pair.
  const double eps = 0.5 * kDegToRad;
  const SE3 step_gt = Translation(0.125, 0, 0);
  const SE3 step_est = SE3(Eigen::Quaterniond(Eigen::AngleAxisd(eps, Eigen::Vector3d::UnitZ())),
                           Eigen::Vector3d(0.125, 0, 0));
  std::vector<SE3> gt = {SE3()}, est = {SE3()};
  for (int k = 1; k < 81; ++k) {
    gt.push_back(gt.back() * step_gt);
    est.push_back(est.back() * step_est);
  }
  double x = 0.0, y = 0.0;
  for (int k = 0; k < 8; ++k) {
    x += 0.125 * std::cos(k * eps);
    y += 0.125 * std::sin(k * eps);
  }
  const double expected_t = std::hypot(x - 1.0, y);  // about 0.0305 m
  absl::StatusOr<RpeResult> rpe = ComputeRpe(est, gt, 1.0, RpePathSource::kGroundTruth);
  ASSERT_TRUE(rpe.ok()) << rpe.status();
  ASSERT_EQ(rpe->pairs.size(), 9u);
  EXPECT_EQ(rpe->pairs.front(), std::make_pair(8, 16));
  EXPECT_NEAR(rpe->rotation_deg.rmse, 4.0, 1e-9);
  EXPECT_NEAR(rpe->rotation_deg.max, 4.0, 1e-9);
  EXPECT_NEAR(rpe->translation_m.rmse, expected_t, 1e-9);
  EXPECT_NEAR(rpe->translation_m.min, expected_t, 1e-9);
}

TEST(RpeTest, ShorterThanTwoDeltasHasNoPairsAndNoError) {
  const std::vector<SE3> line = StraightLine(12, 0.125);  // 1.375 m
  absl::StatusOr<RpeResult> rpe = ComputeRpe(line, line, 1.0);
  ASSERT_TRUE(rpe.ok()) << rpe.status();
  EXPECT_TRUE(rpe->pairs.empty());
  EXPECT_EQ(rpe->translation_m.count, 0);
  EXPECT_TRUE(std::isnan(rpe->translation_m.rmse));
  EXPECT_TRUE(std::isnan(rpe->rotation_deg.rmse));
  EXPECT_DOUBLE_EQ(rpe->path_length_m, 1.375);
  // A single pose, too.
  EXPECT_TRUE(ComputeRpe({SE3()}, {SE3()}, 1.0)->pairs.empty());
  EXPECT_FALSE(ComputeRpe(line, line, 0.0).ok());
  EXPECT_FALSE(ComputeRpe(line, {SE3()}, 1.0).ok());
}

// ---------------------------------------------------------------------------------------------
// EvaluateTrajectory

TEST(TrajectoryEvaluationTest, IdenticalTrajectoriesScoreZero) {
  const std::vector<StampedPose> gt = Helix(400);
  absl::StatusOr<TrajectoryEvalResult> r = EvaluateTrajectory(gt, gt);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->matched, 400);
  EXPECT_EQ(r->estimate_poses, 400);
  EXPECT_EQ(r->ground_truth_poses, 400);
  EXPECT_EQ(r->alignment, TrajectoryAlignment::kNone);
  EXPECT_EQ(r->ate.translation_m.rmse, 0.0);
  EXPECT_GT(r->rpe.pairs.size(), 10u);
  EXPECT_NEAR(r->rpe.translation_m.rmse, 0.0, 1e-12);
  EXPECT_NEAR(r->rpe.rotation_deg.rmse, 0.0, 1e-9);
}

TEST(TrajectoryEvaluationTest, SparseJitteredEstimateAgainstDenseGroundTruth) {
  // Ground truth at 100 Hz (TUM's rate) for 30 s on a 10 m circle (about 1.26 m/s) climbing
  // 0.1 m/s, with no samples between 10.00 and 10.30 s. The estimate: 25 Hz, stamps jittered by
  // up to 4 ms, each pose the true pose at the unjittered stamp plus 0.1 m in x. The jitter is
  // below half the ground-truth period, so every estimate pairs with the sample at its true
  // time, and the error is exactly the offset; estimates 10.04 .. 10.28 s (k = 251..257) are
  // more than 20 ms from any sample and drop out.
  const auto true_pose = [](double t) {
    const double a = 0.02 * t * 2 * M_PI;
    return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ())),
               Eigen::Vector3d(10 * std::cos(a), 10 * std::sin(a), 0.1 * t));
  };
  std::vector<StampedPose> gt;
  for (int k = 0; k < 3000; ++k) {
    if (k > 1000 && k < 1030) continue;
    gt.push_back({0.01 * k, true_pose(0.01 * k)});
  }
  std::vector<StampedPose> est;
  const double jitter[] = {0.0, 0.003, -0.002, 0.001, -0.004};
  for (int k = 0; k < 750; ++k) {
    const double t = 0.04 * k;
    est.push_back({t + jitter[k % 5], Translation(0.1, 0, 0) * true_pose(t)});
  }
  TrajectoryEvalOptions options;
  options.max_dt = 0.02;
  absl::StatusOr<TrajectoryEvalResult> r = EvaluateTrajectory(est, gt, options);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->matched, 743);
  EXPECT_EQ(r->estimate_poses, 750);
  EXPECT_EQ(r->ground_truth_poses, 2971);
  EXPECT_NEAR(r->ate.translation_m.rmse, 0.1, 1e-9);
  EXPECT_NEAR(r->ate.translation_m.max, 0.1, 1e-9);
  // A world-frame offset leaves every relative motion unchanged.
  EXPECT_GT(r->rpe.pairs.size(), 30u);
  EXPECT_NEAR(r->rpe.translation_m.rmse, 0.0, 1e-9);
  EXPECT_NEAR(r->rpe.rotation_deg.rmse, 0.0, 1e-6);

  options.alignment = TrajectoryAlignment::kSE3;
  r = EvaluateTrajectory(est, gt, options);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_NEAR(r->ate.translation_m.rmse, 0.0, 1e-9);
}

TEST(TrajectoryEvaluationTest, Sim3AlignmentAppliesToRpeToo) {
  // Half-size estimate: every relative translation is half the true one, which RPE sees unless
  // the estimate is scaled back first (evo_rpe -as does the same).
  const std::vector<StampedPose> gt = Helix(600);
  std::vector<StampedPose> est = gt;
  const Similarity3 shrink{Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), 0.5};
  for (StampedPose& p : est) p.pose = shrink * p.pose;
  TrajectoryEvalOptions options;
  options.rpe_delta_m = 0.5;
  options.alignment = TrajectoryAlignment::kSE3;
  absl::StatusOr<TrajectoryEvalResult> se3 = EvaluateTrajectory(est, gt, options);
  ASSERT_TRUE(se3.ok()) << se3.status();
  EXPECT_GT(se3->rpe.translation_m.rmse, 0.1);
  options.alignment = TrajectoryAlignment::kSim3;
  absl::StatusOr<TrajectoryEvalResult> sim3 = EvaluateTrajectory(est, gt, options);
  ASSERT_TRUE(sim3.ok()) << sim3.status();
  EXPECT_NEAR(sim3->ate.alignment.scale, 2.0, 1e-9);
  EXPECT_NEAR(sim3->rpe.translation_m.rmse, 0.0, 1e-9);
  // The estimate's path was measured after scaling: twice the pairs of the half-size one.
  EXPECT_GT(sim3->rpe.pairs.size(), se3->rpe.pairs.size());
}

TEST(TrajectoryEvaluationTest, Errors) {
  const std::vector<StampedPose> gt = Helix(50);
  EXPECT_EQ(EvaluateTrajectory({}, gt).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(EvaluateTrajectory(gt, {}).status().code(), absl::StatusCode::kInvalidArgument);

  // Stamps in the wrong units (ms): nothing matches; the message shows both time ranges.
  std::vector<StampedPose> ms = gt;
  for (StampedPose& p : ms) p.timestamp *= 1000.0;
  absl::StatusOr<TrajectoryEvalResult> r = EvaluateTrajectory(ms, gt);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(r.status().message(), HasSubstr("[100000.000000, 104900.000000] s (50 poses)"));
  EXPECT_THAT(r.status().message(), HasSubstr("[100.000000, 104.900000] s (50 poses)"));

  TrajectoryEvalOptions options;
  options.max_dt = -0.01;
  EXPECT_FALSE(EvaluateTrajectory(gt, gt, options).ok());
  options = {};
  options.rpe_delta_m = 0.0;
  EXPECT_FALSE(EvaluateTrajectory(gt, gt, options).ok());
  options = {};
  options.alignment = TrajectoryAlignment::kSE3;
  EXPECT_FALSE(EvaluateTrajectory({gt[0], gt[1]}, gt, options).ok());
  // Short but valid: RPE has no pairs, ATE is reported.
  options = {};
  r = EvaluateTrajectory({gt[0], gt[1]}, gt, options);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->matched, 2);
  EXPECT_TRUE(r->rpe.pairs.empty());
  EXPECT_TRUE(std::isnan(r->rpe.translation_m.rmse));
}

}  // namespace
}  // namespace plx

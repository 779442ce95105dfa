#include "core/datasets/replica_dataset.h"

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <Eigen/SVD>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "core/datasets/dataset.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

constexpr int kWidth = 12;
constexpr int kHeight = 8;

// One traj.txt line: row-major 4x4 with rotation `r` and translation `t`.
std::string TrajLine(const Eigen::Matrix3d& r, const Eigen::Vector3d& t) {
  std::vector<std::string> v;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) v.push_back(absl::StrFormat("%.17g", r(i, j)));
    v.push_back(absl::StrFormat("%.17g", t(i)));
  }
  for (const char* s : {"0", "0", "0", "1"}) v.push_back(s);
  return absl::StrCat(absl::StrJoin(v, " "), "\n");
}

Eigen::Matrix3d RotZ(double angle) {
  return Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

// Frames with the given numbers: colour pattern seed n, depth raw 1000 (n + 1), pose with
// rotation 0.1 n rad about z and translation (n, 0, 0); intrinsics.txt for 12x8.
std::string MakeReplica(const std::string& prefix, const std::vector<int>& numbers,
                        const char* color_extension = ".png") {
  const std::string dir = testing::MakeTempDir(prefix);
  std::string traj;
  for (int n : numbers) {
    testing::WriteImage(absl::StrFormat("%s/results/frame%06d%s", dir, n, color_extension),
                        testing::PatternBgr(kWidth, kHeight, n));
    testing::WriteImage(
        absl::StrFormat("%s/results/depth%06d.png", dir, n),
        testing::ConstantDepth(kWidth, kHeight, static_cast<uint16_t>(1000 * (n + 1))));
  }
  for (size_t i = 0; i < numbers.size(); ++i) {
    traj += TrajLine(RotZ(0.1 * numbers[i]), Eigen::Vector3d(numbers[i], 0, 0));
  }
  testing::WriteTextFile(dir + "/traj.txt", traj);
  testing::WriteTextFile(dir + "/intrinsics.txt", "20 20 6 4 12 8 6553.5\n");
  return dir;
}

TEST(ReplicaDatasetTest, ReadsFramesInNumericOrder) {
  const std::string dir = MakeReplica("replica_good", {0, 1, 2, 10});
  auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const RgbdDataset& d = **dataset;
  ASSERT_EQ(d.size(), 4);
  EXPECT_EQ(d.calibration().depth_scale, 6553.5);
  EXPECT_DOUBLE_EQ(d.timestamp(1), 1 / 30.0);
  EXPECT_DOUBLE_EQ(d.timestamp(3), 10 / 30.0);
  ASSERT_TRUE(d.ground_truth(3).has_value());
  EXPECT_EQ(d.ground_truth(3)->translation(), Eigen::Vector3d(10, 0, 0));
  EXPECT_NEAR(RotationAngleBetween(*d.ground_truth(3), SE3(RotZ(1.0), Eigen::Vector3d::Zero())), 0,
              1e-6);

  auto frame = d.LoadFrame(3);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_FLOAT_EQ(frame->color.pixel(0, 0)[0], 190 / 255.0f);  // R = 200 - 10
  EXPECT_FLOAT_EQ(frame->depth.pixel(2, 2)[0], static_cast<float>(11000 / 6553.5));
  ASSERT_TRUE(frame->ground_truth.has_value());
}

TEST(ReplicaDatasetTest, JpegFramesAndAutoDetection) {
  const std::string dir = MakeReplica("replica_jpg", {0, 1}, ".jpg");
  auto dataset = OpenDataset(dir);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  ASSERT_EQ((*dataset)->size(), 2);
  auto frame = (*dataset)->LoadFrame(1);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_EQ(frame->color.width, kWidth);
  EXPECT_NEAR(frame->color.pixel(5, 5)[0], 199 / 255.0f, 0.05f);  // lossy, roughly right
}

TEST(ReplicaDatasetTest, RotationsAreReOrthonormalised) {
  const std::string dir = MakeReplica("replica_ortho", {0});
  // A slightly scaled and sheared rotation, as text rounding produces.
  Eigen::Matrix3d r = RotZ(0.3) * 1.002;
  r(0, 1) += 0.005;
  r(2, 0) -= 0.003;
  testing::WriteTextFile(dir + "/traj.txt", TrajLine(r, Eigen::Vector3d(1, 2, 3)));
  auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const SE3 pose = *(*dataset)->ground_truth(0);
  // The nearest rotation in the Frobenius sense is U V^T of r's SVD (polar decomposition).
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d nearest = svd.matrixU() * svd.matrixV().transpose();
  EXPECT_LT((pose.rotation_matrix() - nearest).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(pose.translation(), Eigen::Vector3d(1, 2, 3));
}

TEST(ReplicaDatasetTest, TrajectoryLengthMustMatchFrames) {
  const std::string dir = MakeReplica("replica_short_traj", {0, 1, 2});
  testing::WriteTextFile(dir + "/traj.txt", TrajLine(RotZ(0), Eigen::Vector3d::Zero()));
  auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(dataset.status().message(), HasSubstr("traj.txt"));
  EXPECT_THAT(dataset.status().message(), HasSubstr("1 poses"));
  EXPECT_THAT(dataset.status().message(), HasSubstr("3 frames"));
}

TEST(ReplicaDatasetTest, BadTrajectoryLinesNameFileAndLine) {
  const std::string dir = MakeReplica("replica_bad_traj", {0, 1});
  testing::WriteTextFile(dir + "/traj.txt", TrajLine(RotZ(0), Eigen::Vector3d::Zero()) +
                                                "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n");
  auto short_line = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_FALSE(short_line.ok());
  EXPECT_THAT(short_line.status().message(), HasSubstr("traj.txt:2: expected 16 numbers"));
  EXPECT_THAT(short_line.status().message(), HasSubstr("got 15"));

  testing::WriteTextFile(dir + "/traj.txt", TrajLine(RotZ(0), Eigen::Vector3d::Zero()) +
                                                TrajLine(RotZ(0) * 3.0, Eigen::Vector3d::Zero()));
  auto not_rotation = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_FALSE(not_rotation.ok());
  EXPECT_THAT(not_rotation.status().message(), HasSubstr("traj.txt:2: pose rotation"));

  testing::WriteTextFile(dir + "/traj.txt", TrajLine(RotZ(0), Eigen::Vector3d::Zero()) +
                                                "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 2\n");
  auto bottom_row = OpenReplicaDataset(dir, DatasetOptions{});
  ASSERT_FALSE(bottom_row.ok());
  EXPECT_THAT(bottom_row.status().message(), HasSubstr("traj.txt:2: the last row"));
}

TEST(ReplicaDatasetTest, MissingPiecesAreReported) {
  {
    const std::string dir = MakeReplica("replica_no_depth", {0, 1});
    std::filesystem::remove(dir + "/results/depth000001.png");
    auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(dataset.status().message(), HasSubstr("frame000001.png"));
  }
  {
    const std::string dir = MakeReplica("replica_no_traj", {0});
    std::filesystem::remove(dir + "/traj.txt");
    auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(dataset.status().message(), HasSubstr("traj.txt"));
  }
  {
    const std::string dir = MakeReplica("replica_no_intrinsics", {0});
    std::filesystem::remove(dir + "/intrinsics.txt");
    auto dataset = OpenReplicaDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(), HasSubstr("intrinsics.txt is missing"));
  }
  {
    const std::string dir = testing::MakeTempDir("replica_empty");
    std::filesystem::create_directories(dir + "/results");
    testing::WriteTextFile(dir + "/traj.txt", "");
    testing::WriteTextFile(dir + "/intrinsics.txt", "20 20 6 4 12 8 6553.5\n");
    auto dataset = OpenDataset(dir);
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(), HasSubstr("no frames"));
  }
}

TEST(ReplicaDatasetTest, SharedRoom0InTumLayout) {
  const std::string dir = testing::SharedSequence("replica_room0");
  if (dir.empty()) GTEST_SKIP() << "shared data replica_room0 not found";
  auto dataset = OpenDataset(dir);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const RgbdDataset& d = **dataset;
  ASSERT_EQ(d.size(), 20);
  EXPECT_EQ(d.calibration().pinhole, (PinholeIntrinsics{600, 600, 599.5, 339.5, 1200, 680}));
  EXPECT_EQ(d.calibration().depth_scale, 6553.5);
  for (int i = 0; i < d.size(); ++i) {
    EXPECT_NEAR(d.timestamp(i), i / 30.0, 1e-6);
    EXPECT_TRUE(d.ground_truth(i).has_value());
  }
  auto frame = d.LoadFrame(19);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_EQ(frame->color.width, 1200);
  ASSERT_EQ(frame->color.height, 680);
  // Rendered depth: almost no holes (the README says none, but a few frames have up to 4
  // zero pixels) and nothing beyond the room.
  int holes = 0;
  for (float z : frame->depth.data) {
    holes += z == 0.0f;
    ASSERT_LT(z, 10.0f);
  }
  EXPECT_LT(holes, 100);
}

// The shared room0 rearranged into NICE-SLAM's layout (symlinked images, traj.txt from the
// ground truth) must read back as the same sequence.
TEST(ReplicaDatasetTest, SharedRoom0InNiceSlamLayoutMatchesTumLayout) {
  const std::string source = testing::SharedSequence("replica_room0");
  if (source.empty()) GTEST_SKIP() << "shared data replica_room0 not found";
  auto tum = OpenDataset(source);
  ASSERT_TRUE(tum.ok()) << tum.status();
  namespace fs = std::filesystem;
  const std::string dir = testing::MakeTempDir("replica_room0_nice");
  fs::create_directories(dir + "/results");
  fs::copy_file(source + "/intrinsics.txt", dir + "/intrinsics.txt");
  std::string traj;
  for (int i = 0; i < (*tum)->size(); ++i) {
    const std::string stamp = absl::StrFormat("%.6f", (*tum)->timestamp(i));
    fs::create_symlink(fs::absolute(source + "/rgb/" + stamp + ".png"),
                       absl::StrFormat("%s/results/frame%06d.png", dir, i));
    fs::create_symlink(fs::absolute(source + "/depth/" + stamp + ".png"),
                       absl::StrFormat("%s/results/depth%06d.png", dir, i));
    const SE3 pose = *(*tum)->ground_truth(i);
    traj += TrajLine(pose.rotation_matrix(), pose.translation());
  }
  testing::WriteTextFile(dir + "/traj.txt", traj);

  auto replica = OpenDataset(dir);
  ASSERT_TRUE(replica.ok()) << replica.status();
  ASSERT_EQ((*replica)->size(), (*tum)->size());
  for (int i = 0; i < (*tum)->size(); ++i) {
    EXPECT_NEAR((*replica)->timestamp(i), (*tum)->timestamp(i), 1e-6);
    EXPECT_NEAR(RotationAngleBetween(*(*replica)->ground_truth(i), *(*tum)->ground_truth(i)), 0,
                1e-6);
  }
  auto a = (*replica)->LoadFrame(7);
  auto b = (*tum)->LoadFrame(7);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->color.data, b->color.data);
  EXPECT_EQ(a->depth.data, b->depth.data);
}

}  // namespace
}  // namespace plx

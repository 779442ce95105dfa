#include "core/formats/trajectory_file.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// A random unit quaternion (normalised 4-D Gaussian), about half of them with w < 0.
Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
  return q.normalized();
}

// Lines of `text` that are not comments or blank.
std::vector<std::string> DataLines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line[0] != '#') lines.push_back(line);
  }
  return lines;
}

std::string ReadError(const std::string& path) {
  const absl::StatusOr<std::vector<StampedPose>> poses = ReadTumTrajectory(path);
  EXPECT_FALSE(poses.ok()) << path << " was accepted";
  return poses.ok() ? "" : std::string(poses.status().message());
}

TEST(TrajectoryFileTest, WriteThenReadRoundTrips) {
  const std::string dir = testing::MakeTempDir("traj_round_trip");
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> coordinate(-20.0, 20.0);
  std::vector<StampedPose> poses;
  bool some_negative_w = false;
  for (int k = 0; k < 200; ++k) {
    const Eigen::Quaterniond q = RandomRotation(rng);
    some_negative_w |= q.w() < 0;
    // TUM-like stamps: 1.3e9 s, 30 Hz, on the microsecond grid so "%.6f" is exact.
    const double t = 1341841873.0 + std::round(k * 1e6 / 30.0) / 1e6;
    poses.push_back({t, SE3(q, Eigen::Vector3d(coordinate(rng), coordinate(rng),
                                               coordinate(rng)))});
  }
  ASSERT_TRUE(some_negative_w);
  const std::string path = dir + "/est.txt";
  ASSERT_TRUE(WriteTumTrajectory(path, poses, "estimated by plenox\nsequence: test").ok());

  const std::string text = testing::ReadTextFile(path);
  EXPECT_THAT(text, StartsWith("# estimated by plenox\n# sequence: test\n"));
  const std::vector<std::string> lines = DataLines(text);
  ASSERT_EQ(lines.size(), poses.size());
  for (const std::string& line : lines) {
    std::istringstream fields(line);
    std::vector<std::string> f;
    for (std::string s; fields >> s;) f.push_back(s);
    ASSERT_EQ(f.size(), 8u) << line;
    // "%.6f" timestamp, and qw >= 0 whatever sign the quaternion had.
    ASSERT_EQ(f[0].size() - f[0].find('.'), 7u) << line;
    EXPECT_GE(std::stod(f[7]), 0.0) << line;
  }

  const absl::StatusOr<std::vector<StampedPose>> back = ReadTumTrajectory(path);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), poses.size());
  for (size_t k = 0; k < poses.size(); ++k) {
    EXPECT_NEAR((*back)[k].timestamp, poses[k].timestamp, 5e-7);
    // 9 significant digits: |error| <= 5e-9 relative to the value (20 m -> 1e-7 m).
    EXPECT_LT(((*back)[k].pose.translation() - poses[k].pose.translation()).norm(), 2e-7);
    // Quaternion components to 9 significant digits (RotationAngleBetween's acos cannot resolve
    // angles this small); q and -q are the same rotation.
    const Eigen::Vector4d a = (*back)[k].pose.rotation().coeffs();
    const Eigen::Vector4d b = poses[k].pose.rotation().coeffs();
    EXPECT_LT(std::min((a - b).norm(), (a + b).norm()), 5e-9);
  }
  // No temp file is left next to the output.
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
  EXPECT_EQ(entries, 1);
}

TEST(TrajectoryFileTest, ReadsTumGroundTruthLayout) {
  const std::string dir = testing::MakeTempDir("traj_tum_layout");
  const std::string path = dir + "/groundtruth.txt";
  // TUM's header, CRLF line ends, a tab, a blank line, lines out of time order, and a
  // quaternion rounded to 4 decimals (norm not exactly 1), as groundtruth.txt has them.
  testing::WriteTextFile(path,
                         "# ground truth trajectory\r\n"
                         "# file: 'rgbd_dataset_freiburg3_teddy.bag'\r\n"
                         "# timestamp tx ty tz qx qy qz qw\r\n"
                         "1341841873.4251 -2.1802 0.6824 1.4860 -0.2631 0.7903 -0.5176 0.1958\r\n"
                         "\r\n"
                         "1341841873.4151\t-2.1837 0.6821 1.4854 -0.2651 0.7889 -0.5183 0.1970\r\n"
                         "   # an indented comment\r\n"
                         "1341841873.4351 0 0 0 0 0 0 2\r\n");
  const absl::StatusOr<std::vector<StampedPose>> poses = ReadTumTrajectory(path);
  ASSERT_TRUE(poses.ok()) << poses.status();
  ASSERT_EQ(poses->size(), 3u);
  EXPECT_DOUBLE_EQ((*poses)[0].timestamp, 1341841873.4151);
  EXPECT_DOUBLE_EQ((*poses)[1].timestamp, 1341841873.4251);
  EXPECT_DOUBLE_EQ((*poses)[2].timestamp, 1341841873.4351);
  EXPECT_EQ((*poses)[0].pose.translation(), Eigen::Vector3d(-2.1837, 0.6821, 1.4854));
  const Eigen::Quaterniond q0 = Eigen::Quaterniond(0.1970, -0.2651, 0.7889, -0.5183).normalized();
  EXPECT_NEAR(std::abs((*poses)[0].pose.rotation().dot(q0)), 1.0, 1e-12);
  // (0, 0, 0, 2) is normalised to the identity.
  EXPECT_NEAR(RotationAngleBetween((*poses)[2].pose, SE3()), 0.0, 1e-12);
}

TEST(TrajectoryFileTest, EmptyFileHasNoPoses) {
  const std::string dir = testing::MakeTempDir("traj_empty");
  testing::WriteTextFile(dir + "/empty.txt", "# nothing here\n\n");
  const absl::StatusOr<std::vector<StampedPose>> poses = ReadTumTrajectory(dir + "/empty.txt");
  ASSERT_TRUE(poses.ok()) << poses.status();
  EXPECT_TRUE(poses->empty());
}

TEST(TrajectoryFileTest, MissingFileIsNotFound) {
  const absl::StatusOr<std::vector<StampedPose>> poses =
      ReadTumTrajectory(testing::MakeTempDir("traj_missing") + "/nope.txt");
  ASSERT_FALSE(poses.ok());
  EXPECT_EQ(poses.status().code(), absl::StatusCode::kNotFound);
}

TEST(TrajectoryFileTest, MalformedLinesNameFileAndLine) {
  const std::string dir = testing::MakeTempDir("traj_malformed");
  const std::string good = "1.0 0 0 0 0 0 0 1\n";
  struct Case {
    std::string name;
    std::string text;
    std::string expected;  // the whole "path:line: ..." prefix is checked below
  };
  const std::vector<Case> cases = {
      {"seven", "# header\n" + good + "2.0 0 0 0 0 0 1\n", ":3: expected 8 numbers"},
      {"nine", good + "2.0 0 0 0 0 0 0 1 5\n", ":2: expected 8 numbers"},
      {"nan", good + "2.0 0 0 nan 0 0 0 1\n", ":2: field 4 is not finite"},
      {"inf", good + "inf 0 0 0 0 0 0 1\n", ":2: field 1 is not finite"},
      {"word", good + "2.0 0 0 0 0 0 0 one\n", ":2: field 8 is not a number"},
      {"zero_quaternion", good + "\n2.0 1 2 3 0 0 0 0\n", ":3: the quaternion qx qy qz qw is zero"},
      // Out of order, so the duplicates are only neighbours after sorting.
      {"duplicate", "3.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n# c\n3.0 1 1 1 0 0 0 1\n",
       ":4: duplicate timestamp 3 (also on line 1)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir + "/" + c.name + ".txt";
    testing::WriteTextFile(path, c.text);
    EXPECT_THAT(ReadError(path), HasSubstr(path + c.expected));
  }
}

// Found by fuzz_text_files: qx..qw of 1e200 read as a zero quaternion, not a unit one.
TEST(TrajectoryFileTest, HugeQuaternionComponentsNormalise) {
  const std::string path = testing::MakeTempDir("traj_huge_q") + "/t.txt";
  testing::WriteTextFile(path, "1.0 0 0 0 1e200 0 0 1e200\n");
  const absl::StatusOr<std::vector<StampedPose>> poses = ReadTumTrajectory(path);
  ASSERT_TRUE(poses.ok()) << poses.status();
  ASSERT_EQ(poses->size(), 1u);
  const Eigen::Quaterniond& q = (*poses)[0].pose.rotation();
  EXPECT_NEAR(q.norm(), 1.0, 1e-12);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()));
  EXPECT_LT(q.angularDistance(expected), 1e-12);
}

TEST(TrajectoryFileTest, HeaderCommentLinesArePrefixed) {
  const std::string dir = testing::MakeTempDir("traj_header");
  const std::string path = dir + "/t.txt";
  ASSERT_TRUE(WriteTumTrajectory(path, {{1.5, SE3()}}, "a\n\nb\n").ok());
  EXPECT_EQ(testing::ReadTextFile(path), "# a\n#\n# b\n1.500000 0 0 0 0 0 0 1\n");
  ASSERT_TRUE(WriteTumTrajectory(path, {}, "").ok());
  EXPECT_EQ(testing::ReadTextFile(path), "");
}

TEST(TrajectoryFileTest, WriteRejectsWhatCouldNotBeReadBack) {
  const std::string dir = testing::MakeTempDir("traj_bad_write");
  const std::string path = dir + "/t.txt";
  const double nan = std::numeric_limits<double>::quiet_NaN();

  absl::Status s = WriteTumTrajectory(path, {{0.0, SE3()}, {nan, SE3()}});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(s.message(), HasSubstr("not finite"));
  s = WriteTumTrajectory(path, {{0.0, SE3(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(nan, 0, 0))}});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  s = WriteTumTrajectory(path, {{2.0, SE3()}, {1.0, SE3()}});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_THAT(s.message(), HasSubstr("increase"));
  // Distinct doubles that print as the same microsecond.
  s = WriteTumTrajectory(path, {{1.0, SE3()}, {1.0 + 1e-8, SE3()}});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_FALSE(fs::exists(path));

  s = WriteTumTrajectory(dir + "/no/such/folder/t.txt", {{1.0, SE3()}});
  EXPECT_EQ(s.code(), absl::StatusCode::kNotFound) << s;
}

TEST(TrajectoryFileTest, FailedWriteLeavesExistingFileAlone) {
  const std::string dir = testing::MakeTempDir("traj_keep");
  const std::string path = dir + "/t.txt";
  ASSERT_TRUE(WriteTumTrajectory(path, {{1.0, SE3()}}).ok());
  const std::string before = testing::ReadTextFile(path);
  EXPECT_FALSE(WriteTumTrajectory(path, {{2.0, SE3()}, {2.0, SE3()}}).ok());
  EXPECT_EQ(testing::ReadTextFile(path), before);
  // A successful write replaces it.
  ASSERT_TRUE(WriteTumTrajectory(path, {{3.0, SE3()}}).ok());
  EXPECT_EQ(testing::ReadTextFile(path), "3.000000 0 0 0 0 0 0 1\n");
}

}  // namespace
}  // namespace plx

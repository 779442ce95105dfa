#include "core/datasets/tum_dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/datasets/dataset.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace tum_dataset_test {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;

constexpr int kWidth = 8;
constexpr int kHeight = 6;
constexpr char kIntrinsics[] =
    "# fx fy cx cy width height depth_scale k1 k2 p1 p2 k3\n"
    "10 11 4 3 8 6 5000 0 0 0 0 0\n";

std::string Stamp(double t) { return absl::StrFormat("%.6f", t); }

// A TUM sequence with one image per timestamp in rgb/ and depth/, the index files rgb.txt and
// depth.txt (with TUM's 3 comment lines) and intrinsics.txt. Colour frame i uses pattern seed
// i; depth frame j is (j + 1) metres (raw 5000 (j + 1)) except pixel (0, 0).
void WriteTumLists(const std::string& dir, const std::vector<double>& rgb_times,
                   const std::vector<double>& depth_times) {
  std::string rgb = "# color images\n# file: 'test'\n# timestamp filename\n";
  for (size_t i = 0; i < rgb_times.size(); ++i) {
    const std::string name = absl::StrCat("rgb/", Stamp(rgb_times[i]), ".png");
    ASSERT_TRUE(testing::WriteImage(dir + "/" + name,
                                    testing::PatternBgr(kWidth, kHeight, static_cast<int>(i))));
    absl::StrAppend(&rgb, Stamp(rgb_times[i]), " ", name, "\n");
  }
  std::string depth = "# depth maps\n# file: 'test'\n# timestamp filename\n";
  for (size_t j = 0; j < depth_times.size(); ++j) {
    const std::string name = absl::StrCat("depth/", Stamp(depth_times[j]), ".png");
    ASSERT_TRUE(testing::WriteImage(
        dir + "/" + name,
        testing::ConstantDepth(kWidth, kHeight, static_cast<uint16_t>(5000 * (j + 1)))));
    absl::StrAppend(&depth, Stamp(depth_times[j]), " ", name, "\n");
  }
  testing::WriteTextFile(dir + "/rgb.txt", rgb);
  testing::WriteTextFile(dir + "/depth.txt", depth);
  testing::WriteTextFile(dir + "/intrinsics.txt", kIntrinsics);
}

// Three frames at 30 Hz with exact colour/depth timestamps.
std::string MakeSimpleTum(const std::string& prefix) {
  const std::string dir = testing::MakeTempDir(prefix);
  WriteTumLists(dir, {1.0, 1.0 + 1 / 30.0, 1.0 + 2 / 30.0}, {1.0, 1.0 + 1 / 30.0, 1.0 + 2 / 30.0});
  return dir;
}

TEST(TumDatasetTest, AssociatesByTimestampAndDecodesFrames) {
  const std::string dir = MakeSimpleTum("tum_simple");
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const RgbdDataset& d = **dataset;
  EXPECT_EQ(d.size(), 3);
  EXPECT_EQ(d.name(), std::filesystem::path(dir).filename().string());
  EXPECT_EQ(d.calibration().pinhole, (PinholeIntrinsics{10, 11, 4, 3, 8, 6}));
  EXPECT_EQ(d.calibration().depth_scale, 5000.0);
  EXPECT_NEAR(d.timestamp(1), 1.0 + 1 / 30.0, 1e-6);
  EXPECT_FALSE(d.ground_truth(0).has_value());  // no groundtruth.txt

  auto frame = d.LoadFrame(2);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_EQ(frame->color.width, kWidth);
  ASSERT_EQ(frame->color.height, kHeight);
  ASSERT_EQ(frame->color.channels, 3);
  // Pixel (3, 4) of seed 2 is B = 23, G = 44, R = 198; the frame must hold it as RGB.
  const float* rgb = frame->color.pixel(3, 4);
  EXPECT_FLOAT_EQ(rgb[0], 198 / 255.0f);
  EXPECT_FLOAT_EQ(rgb[1], 44 / 255.0f);
  EXPECT_FLOAT_EQ(rgb[2], 23 / 255.0f);
  EXPECT_FLOAT_EQ(frame->depth.pixel(5, 5)[0], 3.0f);
  EXPECT_EQ(frame->depth.pixel(0, 0)[0], 0.0f);
  EXPECT_NEAR(frame->timestamp, d.timestamp(2), 1e-12);
  EXPECT_FALSE(d.LoadFrame(3).ok());
  EXPECT_FALSE(d.LoadFrame(-1).ok());
}

TEST(TumDatasetTest, UsesAssociationsFileWhenPresent) {
  const std::string dir = MakeSimpleTum("tum_assoc");
  // Pair colour 0 with depth 2 and colour 2 with depth 0: only the file can say so.
  testing::WriteTextFile(
      dir + "/associations.txt",
      absl::StrCat(Stamp(1.0 + 2 / 30.0), " rgb/", Stamp(1.0 + 2 / 30.0), ".png ", Stamp(1.0),
                   " depth/", Stamp(1.0), ".png\n", Stamp(1.0), " rgb/", Stamp(1.0), ".png ",
                   Stamp(1.0 + 2 / 30.0), " depth/", Stamp(1.0 + 2 / 30.0), ".png\n"));
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  ASSERT_EQ((*dataset)->size(), 2);
  EXPECT_NEAR((*dataset)->timestamp(0), 1.0, 1e-9);  // sorted by colour time
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_FLOAT_EQ(frame->depth.pixel(1, 1)[0], 3.0f);
}

TEST(TumDatasetTest, AssociationToleranceFollowsOptions) {
  const std::string dir = testing::MakeTempDir("tum_tolerance");
  // Depth offsets from colour: 5 ms, 30 ms, 5 ms.
  WriteTumLists(dir, {0.0, 0.1, 0.2}, {0.005, 0.13, 0.205});
  DatasetOptions strict;
  strict.max_time_difference = 0.02;
  auto a = OpenTumDataset(dir, strict);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_EQ((*a)->size(), 2);
  EXPECT_NEAR((*a)->timestamp(0), 0.0, 1e-9);
  EXPECT_NEAR((*a)->timestamp(1), 0.2, 1e-9);
  auto last = (*a)->LoadFrame(1);
  ASSERT_TRUE(last.ok());
  EXPECT_FLOAT_EQ(last->depth.pixel(1, 1)[0], 3.0f);  // depth entry 2

  DatasetOptions loose;
  loose.max_time_difference = 0.05;
  auto b = OpenTumDataset(dir, loose);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ((*b)->size(), 3);

  DatasetOptions none;
  none.max_time_difference = 0.001;
  auto c = OpenTumDataset(dir, none);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.status().message(), HasSubstr("no colour/depth pairs"));
}

TEST(TumAssociationTest, GreedyBySmallestDifferenceEachEntryOnce) {
  // Both colour frames are within tolerance of the single depth; the closer one wins it.
  EXPECT_THAT(AssociateTimestamps({0.0, 0.01}, {0.008}, 0.02), ElementsAre(Pair(1, 0)));
  // Unsorted input; result sorted by the first list's time.
  EXPECT_THAT(AssociateTimestamps({0.2, 0.0, 0.1}, {0.101, 0.199, 0.001}, 0.02),
              ElementsAre(Pair(1, 2), Pair(2, 0), Pair(0, 1)));
  // The locally best pair is taken first even when that leaves another entry unmatched.
  EXPECT_THAT(AssociateTimestamps({0.0, 0.015}, {0.012, 0.04}, 0.02), ElementsAre(Pair(1, 0)));
  EXPECT_TRUE(AssociateTimestamps({0.0}, {0.5}, 0.02).empty());
  EXPECT_TRUE(AssociateTimestamps({}, {0.5}, 0.02).empty());
}

SE3 RotZ(double angle, const Eigen::Vector3d& t) {
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ())), t);
}

TEST(TumGroundTruthTest, InterpolatesBetweenBracketingSamples) {
  const std::vector<StampedPose> samples = {{0.0, RotZ(0.0, Eigen::Vector3d::Zero())},
                                            {0.02, RotZ(M_PI / 2, Eigen::Vector3d(0.2, 0, 0))}};
  const std::optional<SE3> pose = PoseAtTime(samples, 0.005, 0.02);
  ASSERT_TRUE(pose.has_value());
  EXPECT_NEAR((pose->translation() - Eigen::Vector3d(0.05, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR(RotationAngleBetween(*pose, RotZ(M_PI / 8, Eigen::Vector3d::Zero())), 0, 1e-6);
  // Exactly on a sample.
  const std::optional<SE3> exact = PoseAtTime(samples, 0.02, 0.02);
  ASSERT_TRUE(exact.has_value());
  EXPECT_NEAR((exact->translation() - Eigen::Vector3d(0.2, 0, 0)).norm(), 0, 1e-15);
}

TEST(TumGroundTruthTest, NearestWhenOnlyOneSampleIsCloseAndNoneWhenFar) {
  const std::vector<StampedPose> samples = {{1.0, RotZ(0.0, Eigen::Vector3d(1, 0, 0))},
                                            {1.1, RotZ(0.5, Eigen::Vector3d(2, 0, 0))}};
  const std::optional<SE3> near_first = PoseAtTime(samples, 1.01, 0.02);
  ASSERT_TRUE(near_first.has_value());
  EXPECT_EQ(near_first->translation(), Eigen::Vector3d(1, 0, 0));
  const std::optional<SE3> before_all = PoseAtTime(samples, 0.99, 0.02);
  ASSERT_TRUE(before_all.has_value());
  EXPECT_EQ(before_all->translation(), Eigen::Vector3d(1, 0, 0));
  const std::optional<SE3> after_all = PoseAtTime(samples, 1.115, 0.02);
  ASSERT_TRUE(after_all.has_value());
  EXPECT_EQ(after_all->translation(), Eigen::Vector3d(2, 0, 0));
  EXPECT_FALSE(PoseAtTime(samples, 1.05, 0.02).has_value());
  EXPECT_FALSE(PoseAtTime(samples, 0.9, 0.02).has_value());
  EXPECT_FALSE(PoseAtTime({}, 1.0, 0.02).has_value());
}

TEST(TumDatasetTest, GroundTruthIsInterpolatedPerFrame) {
  const std::string dir = MakeSimpleTum("tum_gt");
  // Samples 10 ms either side of frame 0 (t = 1.0), one 5 ms after frame 1, none near frame 2.
  // Quaternions: identity, and 90 degrees about z as (0, 0, sin 45, cos 45).
  const double s = std::sqrt(0.5);
  testing::WriteTextFile(dir + "/groundtruth.txt",
                         absl::StrFormat("# ground truth trajectory\n"
                                         "# timestamp tx ty tz qx qy qz qw\n"
                                         "0.990000 0 0 0 0 0 0 1\n"
                                         "1.010000 2 0 0 0 0 %.17g %.17g\n"
                                         "%.6f 5 6 7 0 0 0 1\n",
                                         s, s, 1.0 + 1 / 30.0 + 0.005));
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const std::optional<SE3> gt0 = (*dataset)->ground_truth(0);
  ASSERT_TRUE(gt0.has_value());
  EXPECT_NEAR((gt0->translation() - Eigen::Vector3d(1, 0, 0)).norm(), 0, 1e-9);
  EXPECT_NEAR(RotationAngleBetween(*gt0, RotZ(M_PI / 4, Eigen::Vector3d::Zero())), 0, 1e-6);
  const std::optional<SE3> gt1 = (*dataset)->ground_truth(1);
  ASSERT_TRUE(gt1.has_value());
  EXPECT_EQ(gt1->translation(), Eigen::Vector3d(5, 6, 7));
  EXPECT_FALSE((*dataset)->ground_truth(2).has_value());
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_TRUE(frame.ok());
  ASSERT_TRUE(frame->ground_truth.has_value());
  EXPECT_NEAR((frame->ground_truth->translation() - Eigen::Vector3d(1, 0, 0)).norm(), 0, 1e-9);
}

TEST(TumDatasetTest, BadGroundTruthLineNamesFileAndLine) {
  const std::string dir = MakeSimpleTum("tum_bad_gt");
  testing::WriteTextFile(dir + "/groundtruth.txt",
                         "# ground truth\n"
                         "1.0 0 0 0 0 0 0 1\n"
                         "\n"
                         "1.1 0 0 0 0\n");
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(dataset.status().message(),
              HasSubstr("groundtruth.txt:4: expected 8 numbers, got 5"));
}

TEST(TumDatasetTest, NonFiniteAndNonNumericFieldsAreRejected) {
  {
    const std::string dir = MakeSimpleTum("tum_nan_gt");
    testing::WriteTextFile(dir + "/groundtruth.txt", "1.0 0 nan 0 0 0 0 1\n");
    auto dataset = OpenTumDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(), HasSubstr("groundtruth.txt:1: field 3 is not finite"));
  }
  {
    const std::string dir = MakeSimpleTum("tum_bad_quat");
    testing::WriteTextFile(dir + "/groundtruth.txt", "1.0 0 0 0 0 0 0 0\n");
    auto dataset = OpenTumDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(), HasSubstr("groundtruth.txt:1: quaternion"));
  }
  {
    const std::string dir = MakeSimpleTum("tum_bad_rgb");
    testing::WriteTextFile(dir + "/rgb.txt", "# c\n1.0 rgb/1.000000.png\nabc rgb/x.png\n");
    auto dataset = OpenTumDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(),
                HasSubstr("rgb.txt:3: field 1 is not a number: \"abc\""));
  }
  {
    const std::string dir = MakeSimpleTum("tum_bad_assoc");
    testing::WriteTextFile(dir + "/associations.txt", "1.0 rgb/1.000000.png 1.0\n");
    auto dataset = OpenTumDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_THAT(dataset.status().message(), HasSubstr("associations.txt:1: expected 4 fields"));
  }
}

TEST(TumDatasetTest, MissingImageIsReportedAtOpen) {
  const std::string dir = MakeSimpleTum("tum_missing_image");
  std::filesystem::remove(absl::StrCat(dir, "/depth/", Stamp(1.0 + 1 / 30.0), ".png"));
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(dataset.status().message(), HasSubstr(Stamp(1.0 + 1 / 30.0) + ".png"));
  EXPECT_THAT(dataset.status().message(), HasSubstr("depth.txt:5"));
}

TEST(TumDatasetTest, MissingFilesAndDirectories) {
  auto no_dir = OpenTumDataset("/nonexistent/plx/dataset", DatasetOptions{});
  ASSERT_FALSE(no_dir.ok());
  EXPECT_EQ(no_dir.status().code(), absl::StatusCode::kNotFound);

  const std::string dir = MakeSimpleTum("tum_no_depth_list");
  std::filesystem::remove(dir + "/depth.txt");
  auto no_depth = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_FALSE(no_depth.ok());
  EXPECT_EQ(no_depth.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(no_depth.status().message(), HasSubstr("depth.txt"));
}

TEST(TumDatasetTest, EmptyDatasetIsAnError) {
  const std::string dir = MakeSimpleTum("tum_empty");
  testing::WriteTextFile(dir + "/associations.txt", "# nothing here\n");
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(dataset.status().message(), HasSubstr("associations.txt: lists no frames"));
}

TEST(TumDatasetTest, MissingIntrinsicsSaysHowToProvideThem) {
  const std::string dir = MakeSimpleTum("tum_no_intrinsics");
  std::filesystem::remove(dir + "/intrinsics.txt");
  auto missing = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("intrinsics.txt is missing"));
  EXPECT_THAT(missing.status().message(), HasSubstr("flags"));

  DatasetOptions options;
  CameraCalibration flags;
  flags.pinhole = PinholeIntrinsics{20, 20, 4, 3, 8, 6};
  flags.depth_scale = 1000;
  options.calibration = flags;
  auto dataset = OpenTumDataset(dir, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->calibration(), flags);
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_TRUE(frame.ok());
  EXPECT_FLOAT_EQ(frame->depth.pixel(1, 1)[0], 5.0f);  // raw 5000 at depth scale 1000
}

TEST(TumDatasetTest, FlagCalibrationOverridesFile) {
  const std::string dir = MakeSimpleTum("tum_override");
  DatasetOptions options;
  CameraCalibration flags;
  flags.pinhole = PinholeIntrinsics{30, 31, 4, 3, 8, 6};
  flags.depth_scale = 5000;
  options.calibration = flags;
  auto dataset = OpenTumDataset(dir, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->calibration().pinhole.fx, 30);
}

TEST(TumDatasetTest, UndecodableImageFailsInLoadFrameNamingTheFile) {
  const std::string dir = MakeSimpleTum("tum_garbage");
  const std::string path = absl::StrCat(dir, "/rgb/", Stamp(1.0), ".png");
  testing::WriteTextFile(path, "this is not a PNG file");
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();  // decoding is lazy
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(frame.status().message(), HasSubstr(path));
  EXPECT_TRUE((*dataset)->LoadFrame(1).ok());
}

TEST(TumDatasetTest, WrongDepthBitDepthIsRejected) {
  const std::string dir = MakeSimpleTum("tum_8bit_depth");
  const std::string path = absl::StrCat(dir, "/depth/", Stamp(1.0), ".png");
  ASSERT_TRUE(testing::WriteImage(path, cv::Mat(kHeight, kWidth, CV_8UC1, cv::Scalar(10))));
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok());
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(frame.status().message(), HasSubstr(path));
  EXPECT_THAT(frame.status().message(), HasSubstr("16-bit"));
}

TEST(TumDatasetTest, SizeMismatchesNameFilesAndSizes) {
  const std::string dir = MakeSimpleTum("tum_size");
  const std::string depth_path = absl::StrCat(dir, "/depth/", Stamp(1.0), ".png");
  ASSERT_TRUE(testing::WriteImage(depth_path, testing::ConstantDepth(4, 3, 100)));
  const std::string color_path = absl::StrCat(dir, "/rgb/", Stamp(1.0 + 1 / 30.0), ".png");
  const std::string depth_path1 = absl::StrCat(dir, "/depth/", Stamp(1.0 + 1 / 30.0), ".png");
  ASSERT_TRUE(testing::WriteImage(color_path, testing::PatternBgr(4, 3, 0)));
  ASSERT_TRUE(testing::WriteImage(depth_path1, testing::ConstantDepth(4, 3, 100)));
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok());

  auto colour_vs_depth = (*dataset)->LoadFrame(0);
  ASSERT_FALSE(colour_vs_depth.ok());
  EXPECT_THAT(colour_vs_depth.status().message(), HasSubstr(depth_path));
  EXPECT_THAT(colour_vs_depth.status().message(), HasSubstr("8x6"));
  EXPECT_THAT(colour_vs_depth.status().message(), HasSubstr("4x3"));

  auto images_vs_calibration = (*dataset)->LoadFrame(1);
  ASSERT_FALSE(images_vs_calibration.ok());
  EXPECT_THAT(images_vs_calibration.status().message(), HasSubstr(color_path));
  EXPECT_THAT(images_vs_calibration.status().message(), HasSubstr("4x3"));
  EXPECT_THAT(images_vs_calibration.status().message(), HasSubstr("calibration"));
  EXPECT_THAT(images_vs_calibration.status().message(), HasSubstr("8x6"));
}

TEST(TumDatasetTest, DistortedSequenceIsDeliveredUndistorted) {
  const std::string dir = MakeSimpleTum("tum_distorted");
  testing::WriteTextFile(dir + "/intrinsics.txt", "10 11 4 3 8 6 5000 -0.3 0.1 0.01 0 0\n");
  auto dataset = OpenTumDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->calibration().distortion.IsZero());
  EXPECT_EQ((*dataset)->calibration().pinhole, (PinholeIntrinsics{10, 11, 4, 3, 8, 6}));
  auto frame = (*dataset)->LoadFrame(0);
  ASSERT_TRUE(frame.ok()) << frame.status();
  // Depth stays one of the raw values (nearest neighbour) and the image is actually remapped.
  int changed = 0;
  const cv::Mat raw = testing::PatternBgr(kWidth, kHeight, 0);
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const float z = frame->depth.pixel(u, v)[0];
      EXPECT_TRUE(z == 0.0f || z == 1.0f) << z;
      if (std::abs(frame->color.pixel(u, v)[2] * 255.0f - raw.at<cv::Vec3b>(v, u)[0]) > 0.5f) {
        ++changed;
      }
    }
  }
  EXPECT_GT(changed, 0);
}

TEST(TumDatasetTest, RealTeddySequence) {
  const std::string dir = testing::SharedSequence("tum_fr3_teddy");
  if (dir.empty()) GTEST_SKIP() << "shared data tum_fr3_teddy not found";
  auto dataset = OpenDataset(dir);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const RgbdDataset& d = **dataset;
  EXPECT_EQ(d.name(), "tum_fr3_teddy");
  ASSERT_EQ(d.size(), 126);
  EXPECT_EQ(d.calibration().pinhole, (PinholeIntrinsics{535.4, 539.2, 320.1, 247.6, 640, 480}));
  EXPECT_EQ(d.calibration().depth_scale, 5000.0);
  EXPECT_NEAR(d.timestamp(0), 1341841873.405959, 1e-6);
  EXPECT_NEAR(d.timestamp(125), 1341841877.597946, 1e-6);
  for (int i = 0; i < d.size(); ++i) {
    EXPECT_TRUE(d.ground_truth(i).has_value()) << "frame " << i;
    if (i > 0) {
      EXPECT_GT(d.timestamp(i), d.timestamp(i - 1));
    }
  }
  // The first sample (…873.4151) is 9 ms after the first frame: the nearest is used.
  ASSERT_TRUE(d.ground_truth(0).has_value());
  EXPECT_NEAR((d.ground_truth(0)->translation() - Eigen::Vector3d(-2.1837, 0.6821, 1.4854)).norm(),
              0, 1e-9);

  auto frame = d.LoadFrame(0);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_EQ(frame->color.width, 640);
  ASSERT_EQ(frame->color.height, 480);
  ASSERT_EQ(frame->depth.width, 640);
  int valid = 0;
  std::vector<float> depths;
  for (float z : frame->depth.data) {
    if (z > 0) {
      ++valid;
      depths.push_back(z);
    }
  }
  const double valid_fraction = static_cast<double>(valid) / frame->depth.num_pixels();
  EXPECT_GT(valid_fraction, 0.6);
  EXPECT_LT(valid_fraction, 0.9);
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  const float median = depths[depths.size() / 2];
  EXPECT_GT(median, 1.0f);
  EXPECT_LT(median, 4.0f);
  for (float c : frame->color.data) ASSERT_TRUE(c >= 0.0f && c <= 1.0f);
}

TEST(TumDatasetTest, RealTeddyTimestampAssociationMatchesAssociationsFile) {
  const std::string source = testing::SharedSequence("tum_fr3_teddy");
  if (source.empty()) GTEST_SKIP() << "shared data tum_fr3_teddy not found";
  // Same sequence without associations.txt: images by symlink, index files copied.
  namespace fs = std::filesystem;
  const std::string dir = testing::MakeTempDir("tum_teddy_noassoc");
  fs::create_directory_symlink(fs::absolute(source + "/rgb"), dir + "/rgb");
  fs::create_directory_symlink(fs::absolute(source + "/depth"), dir + "/depth");
  for (const char* name : {"rgb.txt", "depth.txt", "groundtruth.txt", "intrinsics.txt"}) {
    fs::copy_file(source + "/" + name, dir + "/" + name);
  }
  auto with_file = OpenDataset(source);
  auto by_time = OpenDataset(dir);
  ASSERT_TRUE(with_file.ok()) << with_file.status();
  ASSERT_TRUE(by_time.ok()) << by_time.status();
  ASSERT_EQ((*by_time)->size(), (*with_file)->size());
  for (int i = 0; i < (*with_file)->size(); ++i) {
    EXPECT_EQ((*by_time)->timestamp(i), (*with_file)->timestamp(i));
  }
  auto a = (*with_file)->LoadFrame(60);
  auto b = (*by_time)->LoadFrame(60);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->depth.data, b->depth.data);
}

TEST(TumDatasetTest, RealTeddyInterpolatedGroundTruthIsCloseToNearestSample) {
  const std::string dir = testing::SharedSequence("tum_fr3_teddy");
  if (dir.empty()) GTEST_SKIP() << "shared data tum_fr3_teddy not found";
  DatasetOptions options;
  auto interpolated = OpenDataset(dir, options);
  // A tolerance below the 10 ms sample spacing leaves at most one sample in reach of a frame:
  // the nearest-sample fallback.
  options.max_time_difference = 0.005;
  auto nearest = OpenDataset(dir, options);
  ASSERT_TRUE(interpolated.ok() && nearest.ok());
  int compared = 0;
  double largest_step = 0;
  for (int i = 0; i < (*interpolated)->size(); ++i) {
    const auto a = (*interpolated)->ground_truth(i);
    const auto b = (*nearest)->ground_truth(i);
    if (!a || !b) continue;
    ++compared;
    largest_step = std::max(largest_step, (a->translation() - b->translation()).norm());
    EXPECT_LT(RotationAngleBetween(*a, *b), 0.01);
  }
  EXPECT_GT(compared, 100);
  // The camera moves well under 1 m/s; 5 ms of motion is a few millimetres.
  EXPECT_LT(largest_step, 0.01);
  EXPECT_GT(largest_step, 0.0);  // interpolation did change something
}

}  // namespace tum_dataset_test
}  // namespace plx

#include "core/datasets/scannet_dataset.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "core/datasets/dataset.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

constexpr int kDepthWidth = 8;
constexpr int kDepthHeight = 6;
constexpr int kColorWidth = 16;
constexpr int kColorHeight = 12;

std::string PoseText(double tx) {
  return absl::StrCat("1 0 0 ", tx, "\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
}

// A ScanNet export with frames `numbers`, written without zero padding. Colour is twice the
// depth size and uniform (R, G, B) = (200, 100, 50) so that JPEG and resizing keep it; depth is
// 2 m (raw 2000 mm) except pixel (0, 0); pose n translates by (n, 0, 0).
std::string MakeScanNet(const std::string& prefix, const std::vector<int>& numbers) {
  const std::string dir = testing::MakeTempDir(prefix);
  for (int n : numbers) {
    testing::WriteImage(absl::StrCat(dir, "/color/", n, ".jpg"),
                        cv::Mat(kColorHeight, kColorWidth, CV_8UC3, cv::Scalar(50, 100, 200)));
    testing::WriteImage(absl::StrCat(dir, "/depth/", n, ".png"),
                        testing::ConstantDepth(kDepthWidth, kDepthHeight, 2000));
    testing::WriteTextFile(absl::StrCat(dir, "/pose/", n, ".txt"), PoseText(n));
  }
  testing::WriteTextFile(dir + "/intrinsic/intrinsic_depth.txt",
                         "7.5 0 3.9 0\n0 7.6 2.9 0\n0 0 1 0\n0 0 0 1\n");
  return dir;
}

TEST(ScanNetDatasetTest, ReadsExportWithNumericOrderAndDepthIntrinsics) {
  const std::string dir = MakeScanNet("scannet_good", {10, 2, 0, 1});
  auto dataset = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const RgbdDataset& d = **dataset;
  ASSERT_EQ(d.size(), 4);
  EXPECT_EQ(d.calibration().pinhole,
            (PinholeIntrinsics{7.5, 7.6, 3.9, 2.9, kDepthWidth, kDepthHeight}));
  EXPECT_EQ(d.calibration().depth_scale, 1000.0);
  const std::vector<double> expected_t = {0.0, 1 / 30.0, 2 / 30.0, 10 / 30.0};
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(d.timestamp(i), expected_t[i]) << i;
  ASSERT_TRUE(d.ground_truth(3).has_value());
  EXPECT_EQ(d.ground_truth(3)->translation(), Eigen::Vector3d(10, 0, 0));

  auto frame = d.LoadFrame(3);
  ASSERT_TRUE(frame.ok()) << frame.status();
  // Colour was resized to the depth size.
  ASSERT_EQ(frame->color.width, kDepthWidth);
  ASSERT_EQ(frame->color.height, kDepthHeight);
  const float* rgb = frame->color.pixel(4, 3);
  EXPECT_NEAR(rgb[0], 200 / 255.0f, 3 / 255.0f);
  EXPECT_NEAR(rgb[1], 100 / 255.0f, 3 / 255.0f);
  EXPECT_NEAR(rgb[2], 50 / 255.0f, 3 / 255.0f);
  EXPECT_FLOAT_EQ(frame->depth.pixel(4, 3)[0], 2.0f);
  EXPECT_EQ(frame->depth.pixel(0, 0)[0], 0.0f);
}

TEST(ScanNetDatasetTest, InvalidPosesMeanNoGroundTruth) {
  const std::string dir = MakeScanNet("scannet_inf", {0, 1});
  testing::WriteTextFile(dir + "/pose/1.txt",
                         "-inf -inf -inf -inf\n-inf -inf -inf -inf\n-inf -inf -inf -inf\n"
                         "-inf -inf -inf -inf\n");
  auto dataset = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->ground_truth(0).has_value());
  EXPECT_FALSE((*dataset)->ground_truth(1).has_value());
  auto frame = (*dataset)->LoadFrame(1);
  ASSERT_TRUE(frame.ok());
  EXPECT_FALSE(frame->ground_truth.has_value());
}

TEST(ScanNetDatasetTest, BadPoseFileNamesFileAndLine) {
  const std::string dir = MakeScanNet("scannet_bad_pose", {0, 1});
  testing::WriteTextFile(dir + "/pose/1.txt", "1 0 0 0\n0 1 x 0\n0 0 1 0\n0 0 0 1\n");
  auto dataset = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(dataset.status().message(), HasSubstr("1.txt:2: field 3 is not a number"));

  testing::WriteTextFile(dir + "/pose/1.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n");
  auto three_rows = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_FALSE(three_rows.ok());
  EXPECT_THAT(three_rows.status().message(), HasSubstr("1.txt"));
  EXPECT_THAT(three_rows.status().message(), HasSubstr("3 rows"));
}

TEST(ScanNetDatasetTest, MissingDepthOrPoseIsReportedAtOpen) {
  {
    const std::string dir = MakeScanNet("scannet_no_depth", {0, 1});
    std::filesystem::remove(dir + "/depth/1.png");
    auto dataset = OpenScanNetDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(dataset.status().message(), HasSubstr("depth/1.png"));
  }
  {
    const std::string dir = MakeScanNet("scannet_no_pose", {0, 1});
    std::filesystem::remove(dir + "/pose/0.txt");
    auto dataset = OpenScanNetDataset(dir, DatasetOptions{});
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(dataset.status().message(), HasSubstr("pose/0.txt"));
  }
}

TEST(ScanNetDatasetTest, CalibrationSources) {
  const std::string dir = MakeScanNet("scannet_calibration", {0});
  // intrinsics.txt wins over intrinsic_depth.txt...
  testing::WriteTextFile(dir + "/intrinsics.txt", "9 9 4 3 8 6 1000\n");
  auto from_file = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_TRUE(from_file.ok()) << from_file.status();
  EXPECT_EQ((*from_file)->calibration().pinhole.fx, 9);
  // ...and flags win over both.
  DatasetOptions options;
  CameraCalibration flags;
  flags.pinhole = PinholeIntrinsics{11, 11, 4, 3, 8, 6};
  options.calibration = flags;
  auto from_flags = OpenScanNetDataset(dir, options);
  ASSERT_TRUE(from_flags.ok()) << from_flags.status();
  EXPECT_EQ((*from_flags)->calibration().pinhole.fx, 11);
  // Neither file nor flags.
  std::filesystem::remove(dir + "/intrinsics.txt");
  std::filesystem::remove(dir + "/intrinsic/intrinsic_depth.txt");
  auto missing = OpenScanNetDataset(dir, DatasetOptions{});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("intrinsics.txt is missing"));
  EXPECT_THAT(missing.status().message(), HasSubstr("intrinsic_depth.txt"));
}

TEST(ScanNetDatasetTest, AutoDetectedAndWithoutPoseFolder) {
  const std::string dir = MakeScanNet("scannet_auto", {0, 1, 2});
  auto detected = OpenDataset(dir);
  ASSERT_TRUE(detected.ok()) << detected.status();
  EXPECT_EQ((*detected)->size(), 3);

  // Without pose/ the layout is not recognised automatically, but can be named.
  std::filesystem::remove_all(dir + "/pose");
  EXPECT_FALSE(OpenDataset(dir).ok());
  DatasetOptions options;
  options.format = DatasetFormat::kScanNet;
  auto named = OpenDataset(dir, options);
  ASSERT_TRUE(named.ok()) << named.status();
  EXPECT_FALSE((*named)->ground_truth(0).has_value());
}

TEST(ScanNetDatasetTest, EmptyExportIsAnError) {
  const std::string dir = testing::MakeTempDir("scannet_empty");
  for (const char* sub : {"color", "depth", "pose"}) {
    std::filesystem::create_directories(dir + "/" + sub);
  }
  auto dataset = OpenDataset(dir);
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(dataset.status().message(), HasSubstr("no frames"));
}

}  // namespace
}  // namespace plx

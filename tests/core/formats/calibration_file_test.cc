#include "core/formats/calibration_file.h"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

// Writes `text` as <fresh dir>/intrinsics.txt and returns its path.
std::string WriteIntrinsics(const std::string& text) {
  const std::string path = testing::MakeTempDir("calibration") + "/intrinsics.txt";
  testing::WriteTextFile(path, text);
  return path;
}

TEST(CalibrationFileTest, ReadsFullLineWithCommentsAndBlankLines) {
  const std::string path = WriteIntrinsics(
      "# fx fy cx cy width height depth_scale k1 k2 p1 p2 k3\n"
      "\n"
      "  # another comment\r\n"
      "535.4 539.2 320.1 247.6 640 480 5000.0 0.1 -0.2 0.001 0.002 0.03\r\n");
  auto calibration = ReadCalibrationFile(path);
  ASSERT_TRUE(calibration.ok()) << calibration.status();
  EXPECT_EQ(calibration->pinhole, (PinholeIntrinsics{535.4, 539.2, 320.1, 247.6, 640, 480}));
  EXPECT_EQ(calibration->depth_scale, 5000.0);
  EXPECT_EQ(calibration->distortion, (Distortion{0.1, -0.2, 0.001, 0.002, 0.03}));
}

TEST(CalibrationFileTest, SevenNumbersMeanNoDistortion) {
  auto calibration = ReadCalibrationFile(WriteIntrinsics("600 600 599.5 339.5 1200 680 6553.5\n"));
  ASSERT_TRUE(calibration.ok()) << calibration.status();
  EXPECT_TRUE(calibration->distortion.IsZero());
  EXPECT_EQ(calibration->depth_scale, 6553.5);
}

TEST(CalibrationFileTest, MalformedFilesNameFileAndLine) {
  struct Case {
    const char* text;
    const char* expected;
  };
  const Case cases[] = {
      {"# header\n535.4 539.2 320.1 247.6 640 480\n", "intrinsics.txt:2: expected 12 numbers"},
      {"# header\n535.4 539.2 320.1 247.6 640.5 480 5000\n",
       "intrinsics.txt:2: field 5 is not an integer"},
      {"535.4 539.2 abc 247.6 640 480 5000\n", "intrinsics.txt:1: field 3 is not a number"},
      {"535.4 nan 320.1 247.6 640 480 5000\n", "intrinsics.txt:1: field 2 is not finite"},
      {"-535.4 539.2 320.1 247.6 640 480 5000\n", "intrinsics.txt:1: focal lengths"},
      {"535.4 539.2 320.1 247.6 640 480 0\n", "intrinsics.txt:1: depth scale"},
      {"535.4 539.2 320.1 247.6 0 480 5000\n", "intrinsics.txt:1: field 5 (image size)"},
      {"535.4 539.2 320.1 247.6 640 480 5000\n# x\n1 1 1 1 1 1 1\n",
       "intrinsics.txt:3: expected a single data line"},
      {"# only a comment\n", "no data line"},
  };
  for (const Case& c : cases) {
    auto calibration = ReadCalibrationFile(WriteIntrinsics(c.text));
    ASSERT_FALSE(calibration.ok()) << c.text;
    EXPECT_EQ(calibration.status().code(), absl::StatusCode::kInvalidArgument) << c.text;
    EXPECT_THAT(calibration.status().message(), HasSubstr(c.expected)) << c.text;
  }
}

TEST(CalibrationFileTest, MissingFileIsNotFound) {
  auto calibration = ReadCalibrationFile("/nonexistent/plx/intrinsics.txt");
  ASSERT_FALSE(calibration.ok());
  EXPECT_EQ(calibration.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(calibration.status().message(), HasSubstr("/nonexistent/plx/intrinsics.txt"));
}

TEST(CalibrationFileTest, WriteThenReadIsExact) {
  CameraCalibration calibration;
  calibration.pinhole = PinholeIntrinsics{535.4, 1.0 / 3.0, 320.1, 247.6, 640, 480};
  calibration.depth_scale = 6553.5;
  calibration.distortion = Distortion{0.1, -1e-7, 0, 2.5e-3, 0.3};
  const std::string path = testing::MakeTempDir("calibration_write") + "/intrinsics.txt";
  ASSERT_TRUE(WriteCalibrationFile(path, calibration).ok());
  auto read = ReadCalibrationFile(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, calibration);
  // Human-readable numbers, not 535.39999999999998.
  EXPECT_THAT(testing::ReadTextFile(path), HasSubstr("535.4 0.3333333333333333 320.1 247.6 640"));
}

TEST(CalibrationFileTest, DatasetCalibrationPrefersFlagsThenFile) {
  const std::string dir = testing::MakeTempDir("calibration_dataset");
  auto missing = LoadDatasetCalibration(dir, std::nullopt);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("intrinsics.txt is missing"));
  EXPECT_THAT(missing.status().message(), HasSubstr("flags"));

  testing::WriteTextFile(dir + "/intrinsics.txt", "10 10 5 5 10 10 1000\n");
  auto from_file = LoadDatasetCalibration(dir, std::nullopt);
  ASSERT_TRUE(from_file.ok()) << from_file.status();
  EXPECT_EQ(from_file->pinhole.fx, 10);

  CameraCalibration flags;
  flags.pinhole = PinholeIntrinsics{20, 20, 5, 5, 10, 10};
  auto from_flags = LoadDatasetCalibration(dir, flags);
  ASSERT_TRUE(from_flags.ok()) << from_flags.status();
  EXPECT_EQ(*from_flags, flags);

  flags.pinhole.fx = 0;
  auto invalid_flags = LoadDatasetCalibration(dir, flags);
  ASSERT_FALSE(invalid_flags.ok());
  EXPECT_THAT(invalid_flags.status().message(), HasSubstr("flags"));
}

TEST(CalibrationFileTest, ReadsScanNetIntrinsicMatrix) {
  const std::string path = testing::MakeTempDir("calibration_matrix") + "/intrinsic_depth.txt";
  testing::WriteTextFile(path,
                         "577.590698 0.000000 318.905426 0.000000\n"
                         "0.000000 578.729797 242.683609 0.000000\n"
                         "0.000000 0.000000 1.000000 0.000000\n"
                         "0.000000 0.000000 0.000000 1.000000\n");
  auto k = ReadIntrinsicMatrixFile(path);
  ASSERT_TRUE(k.ok()) << k.status();
  EXPECT_EQ(k->fx, 577.590698);
  EXPECT_EQ(k->fy, 578.729797);
  EXPECT_EQ(k->cx, 318.905426);
  EXPECT_EQ(k->cy, 242.683609);
  EXPECT_EQ(k->width, 0);

  testing::WriteTextFile(path, "577 0 318 0\n0 578 242\n0 0 1 0\n0 0 0 1\n");
  auto bad = ReadIntrinsicMatrixFile(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("intrinsic_depth.txt:2: expected 4 numbers"));
}

}  // namespace
}  // namespace plx

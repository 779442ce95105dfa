#include "core/io/image_io.h"

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Core>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

std::string TempFile(const std::string& name) {
  return testing::MakeTempDir("image_io") + "/" + name;
}

TEST(ImageIoTest, ColourIsConvertedFromBgrToRgb) {
  const std::string path = TempFile("c.png");
  cv::Mat bgr(2, 3, CV_8UC3, cv::Scalar(0, 0, 0));
  bgr.at<cv::Vec3b>(1, 2) = cv::Vec3b(0, 0, 255);  // pure red in OpenCV order
  bgr.at<cv::Vec3b>(0, 1) = cv::Vec3b(51, 102, 0);
  ASSERT_TRUE(testing::WriteImage(path, bgr));
  auto image = ReadColorImage(path);
  ASSERT_TRUE(image.ok()) << image.status();
  ASSERT_EQ(image->width, 3);
  ASSERT_EQ(image->height, 2);
  ASSERT_EQ(image->channels, 3);
  EXPECT_EQ(image->pixel(2, 1)[0], 1.0f);
  EXPECT_EQ(image->pixel(2, 1)[1], 0.0f);
  EXPECT_EQ(image->pixel(2, 1)[2], 0.0f);
  EXPECT_FLOAT_EQ(image->pixel(1, 0)[1], 0.4f);
  EXPECT_FLOAT_EQ(image->pixel(1, 0)[2], 0.2f);
}

TEST(ImageIoTest, GreyIsReplicatedAndAlphaDropped) {
  const std::string grey_path = TempFile("grey.png");
  ASSERT_TRUE(testing::WriteImage(grey_path, cv::Mat(2, 2, CV_8UC1, cv::Scalar(77))));
  auto grey = ReadColorImage(grey_path);
  ASSERT_TRUE(grey.ok()) << grey.status();
  for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(grey->pixel(1, 1)[c], 77 / 255.0f);

  const std::string alpha_path = TempFile("alpha.png");
  ASSERT_TRUE(testing::WriteImage(alpha_path, cv::Mat(2, 2, CV_8UC4, cv::Scalar(10, 20, 30, 40))));
  auto alpha = ReadColorImage(alpha_path);
  ASSERT_TRUE(alpha.ok()) << alpha.status();
  ASSERT_EQ(alpha->channels, 3);
  EXPECT_FLOAT_EQ(alpha->pixel(0, 1)[0], 30 / 255.0f);
  EXPECT_FLOAT_EQ(alpha->pixel(0, 1)[1], 20 / 255.0f);
  EXPECT_FLOAT_EQ(alpha->pixel(0, 1)[2], 10 / 255.0f);
}

TEST(ImageIoTest, WrongBitDepthsAreRejectedWithFileAndShape) {
  const std::string colour16 = TempFile("c16.png");
  ASSERT_TRUE(testing::WriteImage(colour16, cv::Mat(2, 2, CV_16UC3, cv::Scalar(1, 2, 3))));
  auto colour = ReadColorImage(colour16);
  ASSERT_FALSE(colour.ok());
  EXPECT_EQ(colour.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(colour.status().message(), HasSubstr(colour16));
  EXPECT_THAT(colour.status().message(), HasSubstr("8-bit"));
  EXPECT_THAT(colour.status().message(), HasSubstr("16-bit unsigned"));

  const std::string depth8 = TempFile("d8.png");
  ASSERT_TRUE(testing::WriteImage(depth8, cv::Mat(2, 2, CV_8UC1, cv::Scalar(9))));
  auto depth = ReadDepthImage(depth8, 1000);
  ASSERT_FALSE(depth.ok());
  EXPECT_THAT(depth.status().message(), HasSubstr(depth8));
  EXPECT_THAT(depth.status().message(), HasSubstr("16-bit"));
  EXPECT_THAT(depth.status().message(), HasSubstr("2x2, 8-bit unsigned, 1 channel"));

  const std::string depth3 = TempFile("d3.png");
  ASSERT_TRUE(testing::WriteImage(depth3, cv::Mat(2, 2, CV_16UC3, cv::Scalar(9, 9, 9))));
  auto depth_rgb = ReadDepthImage(depth3, 1000);
  ASSERT_FALSE(depth_rgb.ok());
  EXPECT_THAT(depth_rgb.status().message(), HasSubstr("3 channels"));
}

TEST(ImageIoTest, UnreadableAndMissingFiles) {
  const std::string garbage = TempFile("garbage.png");
  testing::WriteTextFile(garbage, "\x89PNG but not really");
  auto colour = ReadColorImage(garbage);
  ASSERT_FALSE(colour.ok());
  EXPECT_EQ(colour.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(colour.status().message(), HasSubstr(garbage));
  EXPECT_FALSE(ReadDepthImage(garbage, 1000).ok());

  auto missing = ReadDepthImage("/nonexistent/plx/d.png", 1000);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("/nonexistent/plx/d.png"));
}

TEST(ImageIoTest, DepthIsScaledToMetres) {
  const std::string path = TempFile("d.png");
  cv::Mat raw(1, 3, CV_16UC1);
  raw.at<uint16_t>(0, 0) = 0;
  raw.at<uint16_t>(0, 1) = 5000;
  raw.at<uint16_t>(0, 2) = 65535;
  ASSERT_TRUE(testing::WriteImage(path, raw));
  auto depth = ReadDepthImage(path, 5000);
  ASSERT_TRUE(depth.ok()) << depth.status();
  EXPECT_EQ(depth->data[0], 0.0f);
  EXPECT_EQ(depth->data[1], 1.0f);
  EXPECT_FLOAT_EQ(depth->data[2], 13.107f);
  EXPECT_FALSE(ReadDepthImage(path, 0).ok());
}

// Found by fuzz_frame_proto: a denormal depth_scale (a positive, finite 1e-310 from a client)
// has an infinite inverse, and 0 * inf turned every "no measurement" pixel into NaN, which
// slips through "z <= 0 || z > max_depth" (depth fusion). Zero must stay zero at any scale.
TEST(ImageIoTest, ZeroDepthStaysZeroAtAnyScale) {
  cv::Mat raw(1, 2, CV_16UC1);
  raw.at<uint16_t>(0, 0) = 0;
  raw.at<uint16_t>(0, 1) = 7;
  const std::string bytes("\x00\x00\x07\x00", 4);  // the same two samples, little-endian
  for (const double scale : {5000.0, 1e-300, 1e-310, 4.9e-324}) {
    SCOPED_TRACE(scale);
    for (const DepthImage& depth :
         {DepthImageFromMat(raw, scale), DepthImageFromU16Bytes(bytes, 2, 1, scale)}) {
      ASSERT_EQ(depth.data.size(), 2u);
      EXPECT_EQ(depth.data[0], 0.0f);
      EXPECT_FALSE(std::isnan(depth.data[1]));
      EXPECT_GT(depth.data[1], 0.0f);
    }
  }
}

TEST(ImageIoTest, U16BytesRoundTrip) {
  DepthImage depth(3, 1, 1);
  depth.data[0] = 0.0f;
  depth.data[1] = 1.0f;
  depth.data[2] = 2.5f;
  const DepthImage back =
      DepthImageFromU16Bytes(DepthImageToU16Bytes(depth, 1000.0), 3, 1, 1000.0);
  EXPECT_EQ(back.width, 3);
  EXPECT_EQ(back.height, 1);
  EXPECT_EQ(std::vector<float>(back.data.begin(), back.data.end()),
            (std::vector<float>{0.0f, 1.0f, 2.5f}));
}

TEST(ImageIoTest, WriteThenReadRoundTrips) {
  ColorImage colour(4, 3, 3);
  for (size_t i = 0; i < colour.data.size(); ++i) colour.data[i] = static_cast<float>(i) / 40.0f;
  colour.data[0] = 1.7f;                                     // clamped to 1
  colour.data[1] = -0.3f;                                    // clamped to 0
  colour.data[2] = std::numeric_limits<float>::quiet_NaN();  // written as 0
  const std::string colour_path = TempFile("c.png");
  ASSERT_TRUE(WriteColorImage(colour_path, colour).ok());
  auto colour_back = ReadColorImage(colour_path);
  ASSERT_TRUE(colour_back.ok()) << colour_back.status();
  EXPECT_EQ(colour_back->data[0], 1.0f);
  EXPECT_EQ(colour_back->data[1], 0.0f);
  EXPECT_EQ(colour_back->data[2], 0.0f);
  for (size_t i = 3; i < colour.data.size(); ++i) {
    EXPECT_NEAR(colour_back->data[i], colour.data[i], 0.5f / 255.0f + 1e-6f) << i;
  }

  DepthImage depth(6, 1, 1);
  depth.data = {0.0f,
                -1.0f,
                std::numeric_limits<float>::quiet_NaN(),
                std::numeric_limits<float>::infinity(),
                1.23456f,
                20.0f};
  const std::string depth_path = TempFile("d.png");
  ASSERT_TRUE(WriteDepthImage(depth_path, depth, 5000).ok());
  const cv::Mat raw = cv::imread(depth_path, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(raw.type(), CV_16UC1);
  EXPECT_EQ(raw.at<uint16_t>(0, 0), 0);
  EXPECT_EQ(raw.at<uint16_t>(0, 1), 0);
  EXPECT_EQ(raw.at<uint16_t>(0, 2), 0);
  EXPECT_EQ(raw.at<uint16_t>(0, 3), 0);
  EXPECT_EQ(raw.at<uint16_t>(0, 4), 6173);   // round(1.23456 * 5000)
  EXPECT_EQ(raw.at<uint16_t>(0, 5), 65535);  // 100000 clamped

  // Wrong channel counts (a depth image passed as colour no longer compiles: image.h).
  EXPECT_FALSE(WriteColorImage(TempFile("bad.png"), ColorImage(2, 2, 1)).ok());
  EXPECT_FALSE(WriteDepthImage(TempFile("bad.png"), DepthImage(2, 2, 3), 1000).ok());
  EXPECT_FALSE(WriteColorImage("/nonexistent/plx/c.png", colour).ok());
}

// Brown-Conrady in OpenCV's convention on normalised coordinates.
Eigen::Vector2d Distort(const Eigen::Vector2d& p, const Distortion& d) {
  const double x = p.x(), y = p.y(), r2 = x * x + y * y;
  const double radial = 1 + d.k1 * r2 + d.k2 * r2 * r2 + d.k3 * r2 * r2 * r2;
  return {x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x),
          y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y};
}

// The ideal (undistorted) normalised point that distorts to `pd`, by fixed-point iteration.
Eigen::Vector2d Undistort(const Eigen::Vector2d& pd, const Distortion& d) {
  Eigen::Vector2d p = pd;
  for (int i = 0; i < 100; ++i) p += pd - Distort(p, d);
  return p;
}

struct SyntheticCamera {
  CameraCalibration calibration;
  SyntheticCamera() {
    calibration.pinhole = PinholeIntrinsics{120, 125, 82, 57, 160, 120};
    calibration.depth_scale = 1000;
    calibration.distortion = Distortion{-0.25, 0.08, 0.002, -0.0015, 0};
  }
  // Renders f(ideal pixel position) as seen through the distorting lens, pixel centres at +0.5.
  cv::Mat RenderDistorted(int type, const std::function<double(double, double)>& f) const {
    const PinholeIntrinsics& k = calibration.pinhole;
    cv::Mat image(k.height, k.width, type);
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const Eigen::Vector2d pd((u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy);
        const Eigen::Vector2d p = Undistort(pd, calibration.distortion);
        EXPECT_LT((Distort(p, calibration.distortion) - pd).norm(), 1e-9);
        const double value = f(p.x() * k.fx + k.cx, p.y() * k.fy + k.cy);
        if (type == CV_8UC1) {
          image.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(value);
        } else {
          image.at<uint16_t>(v, u) = cv::saturate_cast<uint16_t>(value);
        }
      }
    }
    return image;
  }
  cv::Mat RenderIdeal(int type, const std::function<double(double, double)>& f) const {
    const PinholeIntrinsics& k = calibration.pinhole;
    cv::Mat image(k.height, k.width, type);
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const double value = f(u + 0.5, v + 0.5);
        if (type == CV_8UC1) {
          image.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(value);
        } else {
          image.at<uint16_t>(v, u) = cv::saturate_cast<uint16_t>(value);
        }
      }
    }
    return image;
  }
};

TEST(ImageIoUndistortTest, DistortedPatternMovesCloserToTruth) {
  const SyntheticCamera camera;
  // Smooth enough for bilinear sampling, structured enough that a 10-pixel shift shows.
  const auto pattern = [](double x, double y) {
    return 127.5 + 120 * std::sin(x / 7.0) * std::cos(y / 9.0);
  };
  cv::Mat distorted, truth;
  cv::cvtColor(camera.RenderDistorted(CV_8UC1, pattern), distorted, cv::COLOR_GRAY2RGB);
  cv::cvtColor(camera.RenderIdeal(CV_8UC1, pattern), truth, cv::COLOR_GRAY2RGB);

  auto undistorter = Undistorter::Create(camera.calibration);
  ASSERT_TRUE(undistorter.ok()) << undistorter.status();
  auto undistorted = undistorter->UndistortColor(distorted);
  ASSERT_TRUE(undistorted.ok()) << undistorted.status();
  ASSERT_EQ(undistorted->type(), CV_8UC3);

  // Barrel distortion: every output pixel has a source inside the image; skip a thin border.
  double before = 0, after = 0;
  int count = 0;
  for (int v = 2; v < truth.rows - 2; ++v) {
    for (int u = 2; u < truth.cols - 2; ++u) {
      const double t = truth.at<cv::Vec3b>(v, u)[0];
      before += std::abs(distorted.at<cv::Vec3b>(v, u)[0] - t);
      after += std::abs(undistorted->at<cv::Vec3b>(v, u)[0] - t);
      ++count;
    }
  }
  before /= count;
  after /= count;
  EXPECT_GT(before, 20.0);  // the lens really moved the pattern
  // About 0.25 grey levels (bilinear and 8-bit rounding); ignoring the half-pixel centre
  // convention puts the distortion centre off by half a pixel and gives about 0.6.
  EXPECT_LT(after, 0.45);
}

TEST(ImageIoUndistortTest, DepthIsResampledWithoutBlending) {
  const SyntheticCamera camera;
  // A near disc (1 m) in front of a far wall (3 m), with a sharp edge.
  const auto scene = [](double x, double y) {
    return std::hypot(x - 120, y - 35) < 22 ? 1000.0 : 3000.0;
  };
  const cv::Mat distorted = camera.RenderDistorted(CV_16UC1, scene);
  const cv::Mat truth = camera.RenderIdeal(CV_16UC1, scene);
  auto undistorter = Undistorter::Create(camera.calibration);
  ASSERT_TRUE(undistorter.ok());
  auto undistorted = undistorter->UndistortDepth(distorted);
  ASSERT_TRUE(undistorted.ok()) << undistorted.status();
  ASSERT_EQ(undistorted->type(), CV_16UC1);

  int matches = 0, matches_before = 0;
  for (int v = 0; v < truth.rows; ++v) {
    for (int u = 0; u < truth.cols; ++u) {
      const uint16_t z = undistorted->at<uint16_t>(v, u);
      ASSERT_TRUE(z == 0 || z == 1000 || z == 3000) << "blended depth " << z;
      matches += z == truth.at<uint16_t>(v, u);
      matches_before += distorted.at<uint16_t>(v, u) == truth.at<uint16_t>(v, u);
    }
  }
  const int total = truth.rows * truth.cols;
  EXPECT_GT(matches, 0.99 * total);  // only rounding at the disc's edge may differ
  EXPECT_LT(matches_before, matches);
}

TEST(ImageIoUndistortTest, ZeroDistortionIsIdentityAndSizeIsChecked) {
  CameraCalibration calibration;
  calibration.pinhole = PinholeIntrinsics{50, 50, 16, 12, 32, 24};
  auto undistorter = Undistorter::Create(calibration);
  ASSERT_TRUE(undistorter.ok());
  const cv::Mat colour = testing::PatternBgr(32, 24, 3);
  auto same = undistorter->UndistortColor(colour);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(cv::norm(*same, colour, cv::NORM_INF), 0.0);

  auto wrong_size = undistorter->UndistortDepth(cv::Mat(10, 10, CV_16UC1, cv::Scalar(1)));
  ASSERT_FALSE(wrong_size.ok());
  EXPECT_THAT(wrong_size.status().message(), HasSubstr("10x10"));
  EXPECT_THAT(wrong_size.status().message(), HasSubstr("32x24"));

  calibration.pinhole.fx = -1;
  EXPECT_FALSE(Undistorter::Create(calibration).ok());
}

}  // namespace
}  // namespace plx

// PNG buffers are decoded with libpng directly: the same images as OpenCV's imdecode, and a
// corrupt PNG's error comes back as a Status with libpng's reason, with nothing on stderr (the
// daemon's log is logfmt lines; OpenCV let libpng print "libpng error: ..." between them).
#include "core/io/png_decode.h"

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/io/image_io.h"

namespace plx {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

cv::Mat Noise(int type) {
  cv::Mat image(13, 17, type);  // odd sizes: rows are not word multiples
  cv::randu(image, 0, CV_MAT_DEPTH(type) == CV_16U ? 65536 : 256);
  return image;
}

std::string Png(const cv::Mat& image, const std::vector<int>& params = {}) {
  std::vector<uint8_t> bytes;
  EXPECT_TRUE(cv::imencode(".png", image, bytes, params));
  return std::string(bytes.begin(), bytes.end());
}

void ExpectSameAsOpenCv(const std::string& png) {
  const cv::Mat expected =
      cv::imdecode(cv::Mat(1, static_cast<int>(png.size()), CV_8UC1, const_cast<char*>(png.data())),
                   cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(expected.empty());
  const absl::StatusOr<cv::Mat> decoded = DecodePng(png, "frame.color");
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  ASSERT_EQ(decoded->type(), expected.type());
  ASSERT_EQ(decoded->size(), expected.size());
  EXPECT_EQ(cv::norm(*decoded, expected, cv::NORM_INF), 0.0);
}

TEST(PngDecodeTest, GivesOpenCvsImagesForEveryLayoutItWrites) {
  for (const int type : {CV_8UC1, CV_8UC3, CV_8UC4, CV_16UC1, CV_16UC3, CV_16UC4}) {
    SCOPED_TRACE(type);
    ExpectSameAsOpenCv(Png(Noise(type)));
  }
  // 1-bit grey is expanded to 8 bits.
  cv::Mat bilevel = Noise(CV_8UC1) > 127;
  ExpectSameAsOpenCv(Png(bilevel, {cv::IMWRITE_PNG_BILEVEL, 1}));
}

// The IDAT chunk's first data byte: the zlib header.
size_t IdatDataOffset(const std::string& png) {
  const size_t type = png.find("IDAT");
  EXPECT_NE(type, std::string::npos);
  return type + 4;
}

// The IDAT chunk's data length (big-endian, before its type).
uint32_t IdatLength(const std::string& png) {
  const size_t data = IdatDataOffset(png);
  uint32_t length = 0;
  for (size_t i = data - 8; i < data - 4; ++i) {
    length = (length << 8) | static_cast<uint8_t>(png[i]);
  }
  return length;
}

TEST(PngDecodeTest, ACorruptPngIsAnErrorWithLibpngsReasonAndNothingOnStderr) {
  std::string png = Png(Noise(CV_8UC3));
  png[IdatDataOffset(png) + IdatLength(png)] ^= 0x5A;  // the chunk's CRC itself
  ::testing::internal::CaptureStderr();
  const absl::StatusOr<cv::Mat> crc = DecodePng(png, "frame.color");
  const absl::StatusOr<cv::Mat> via_image_io = DecodeColorBuffer(png, "frame[2].color");
  const std::string truncated_png = Png(Noise(CV_16UC1));
  const absl::StatusOr<cv::Mat> truncated =
      DecodeDepthBuffer(truncated_png.substr(0, IdatDataOffset(truncated_png) + 20), "frame.depth");
  EXPECT_THAT(::testing::internal::GetCapturedStderr(), IsEmpty());

  EXPECT_EQ(crc.status().code(), absl::StatusCode::kInvalidArgument) << crc.status();
  EXPECT_THAT(std::string(crc.status().message()),
              AllOf(HasSubstr("frame.color: cannot decode PNG: "), HasSubstr("CRC error")));
  EXPECT_EQ(via_image_io.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(via_image_io.status().message()),
              AllOf(HasSubstr("frame[2].color: cannot decode PNG: "), HasSubstr("CRC error")));
  EXPECT_EQ(truncated.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(truncated.status().message()),
              HasSubstr("frame.depth: cannot decode PNG: truncated"));
}

// The data stream itself is bad (the CRC matches what was sent): zlib's reason, via libpng.
TEST(PngDecodeTest, BadCompressedDataNamesZlibsReason) {
  std::string png = Png(Noise(CV_8UC1));
  const size_t data = IdatDataOffset(png);
  png[data] = 0x00;  // not a zlib header
  // Recompute the chunk's CRC (over type and data) so that the data, not the CRC, is wrong.
  const uint32_t length = IdatLength(png);
  uint32_t crc = 0xFFFFFFFFu;
  for (size_t i = data - 4; i < data + length; ++i) {
    crc ^= static_cast<uint8_t>(png[i]);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  crc ^= 0xFFFFFFFFu;
  for (int k = 0; k < 4; ++k) png[data + length + k] = static_cast<char>(crc >> (24 - 8 * k));
  ::testing::internal::CaptureStderr();
  const absl::StatusOr<cv::Mat> decoded = DecodePng(png, "frame.depth");
  EXPECT_THAT(::testing::internal::GetCapturedStderr(), IsEmpty());
  EXPECT_EQ(decoded.status().code(), absl::StatusCode::kInvalidArgument) << decoded.status();
  EXPECT_THAT(std::string(decoded.status().message()),
              AllOf(HasSubstr("frame.depth: cannot decode PNG: IDAT: "), HasSubstr("header")))
      << "zlib's incorrect header check";
}

}  // namespace
}  // namespace plx

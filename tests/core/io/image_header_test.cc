#include "core/io/image_header.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/io/image_io.h"
#include "tests/image_bytes.h"

namespace plx {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

std::string Encode(const cv::Mat& image, const std::string& extension) {
  std::vector<uint8_t> bytes;
  EXPECT_TRUE(cv::imencode(extension, image, bytes));
  return std::string(bytes.begin(), bytes.end());
}

TEST(ImageHeaderTest, ReadsWhatOpenCvsEncodersWrite) {
  const struct {
    cv::Mat image;
    const char* extension;
    ImageFormat format;
    int channels, bit_depth;
  } cases[] = {
      {cv::Mat(7, 5, CV_8UC3, cv::Scalar(1, 2, 3)), ".png", ImageFormat::kPng, 3, 8},
      {cv::Mat(7, 5, CV_8UC1, cv::Scalar(9)), ".png", ImageFormat::kPng, 1, 8},
      {cv::Mat(7, 5, CV_8UC4, cv::Scalar(1, 2, 3, 4)), ".png", ImageFormat::kPng, 4, 8},
      {cv::Mat(7, 5, CV_16UC1, cv::Scalar(5000)), ".png", ImageFormat::kPng, 1, 16},
      {cv::Mat(7, 5, CV_8UC3, cv::Scalar(1, 2, 3)), ".jpg", ImageFormat::kJpeg, 3, 8},
      {cv::Mat(7, 5, CV_8UC1, cv::Scalar(9)), ".jpg", ImageFormat::kJpeg, 1, 8},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(::testing::Message() << c.extension << " " << c.channels << "x" << c.bit_depth);
    absl::StatusOr<ImageHeader> h = ReadImageHeader(Encode(c.image, c.extension), "img");
    ASSERT_TRUE(h.ok()) << h.status();
    EXPECT_EQ(h->format, c.format);
    EXPECT_EQ(h->width, 5);
    EXPECT_EQ(h->height, 7);
    EXPECT_EQ(h->channels, c.channels);
    EXPECT_EQ(h->bit_depth, c.bit_depth);
  }
}

TEST(ImageHeaderTest, ABombsDeclaredSizeIsReadFromItsFirstBytes) {
  const std::string bomb = testing::PngDeclaring(16384, 16384);
  ASSERT_LT(bomb.size(), 100u);
  absl::StatusOr<ImageHeader> h = ReadImageHeader(bomb, "frame.color");
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(h->width, 16384);
  EXPECT_EQ(h->height, 16384);
  // The largest size PNG allows, and JPEG's.
  h = ReadImageHeader(testing::PngDeclaring(0x7FFFFFFF, 0x7FFFFFFF), "x");
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(h->width, 0x7FFFFFFF);
  h = ReadImageHeader(testing::JpegHeaderDeclaring(65535, 65535), "x");
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(h->format, ImageFormat::kJpeg);
  EXPECT_EQ(h->width, 65535);
  EXPECT_EQ(h->height, 65535);
  EXPECT_EQ(h->channels, 3);
}

TEST(ImageHeaderTest, JpegSegmentsBeforeTheFrameHeaderAreSkipped) {
  // APP0, a fill byte and COM come before SOF0 (testing::JpegHeaderDeclaring).
  absl::StatusOr<ImageHeader> h = ReadImageHeader(testing::JpegHeaderDeclaring(640, 480, 1), "x");
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(h->width, 640);
  EXPECT_EQ(h->height, 480);
  EXPECT_EQ(h->channels, 1);
  EXPECT_EQ(h->bit_depth, 8);
}

// Every prefix shorter than the header is refused with a message naming the source; none is
// read past its end (the prefixes are copies, so a sanitiser would see an overrun).
TEST(ImageHeaderTest, EveryTruncatedHeaderIsRefused) {
  const std::string png = testing::PngDeclaring(64, 48);
  for (size_t n = 0; n < 29; ++n) {
    const std::string prefix = png.substr(0, n);
    EXPECT_FALSE(ReadImageHeader(prefix, "c").ok()) << n << " bytes";
  }
  EXPECT_TRUE(ReadImageHeader(png.substr(0, 29), "c").ok());
  const std::string jpeg = testing::JpegHeaderDeclaring(64, 48);
  for (size_t n = 0; n < jpeg.size(); ++n) {
    const std::string prefix = jpeg.substr(0, n);
    absl::StatusOr<ImageHeader> h = ReadImageHeader(prefix, "c");
    EXPECT_FALSE(h.ok()) << n << " bytes";
    if (!h.ok()) {
      EXPECT_THAT(h.status().message(), HasSubstr("c: "));
    }
  }
  EXPECT_TRUE(ReadImageHeader(jpeg, "c").ok());
}

TEST(ImageHeaderTest, MalformedHeadersAreRefused) {
  const auto refused = [](const std::string& bytes, const std::string& says) {
    absl::StatusOr<ImageHeader> h = ReadImageHeader(bytes, "frame.color");
    ASSERT_FALSE(h.ok());
    EXPECT_EQ(h.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(h.status().message(), AllOf(HasSubstr("frame.color: "), HasSubstr(says)));
  };
  refused("", "empty");
  refused("definitely not an image", "not a PNG or JPEG");
  refused(Encode(cv::Mat(4, 4, CV_8UC3), ".bmp"), "not a PNG or JPEG");
  refused(testing::PngDeclaring(0, 10), "invalid size 0x10");
  refused(testing::PngDeclaring(0x80000000u, 1), "invalid size");
  refused(testing::PngDeclaring(8, 8, /*colour_type=*/2, /*bit_depth=*/4), "bit depth 4");
  refused(testing::PngDeclaring(8, 8, /*colour_type=*/5), "colour type 5");
  std::string no_ihdr = testing::PngDeclaring(8, 8);
  no_ihdr[12] = 'X';
  refused(no_ihdr, "IHDR");
  // JPEG: a scan before any frame header, a zero height (DNL), a segment longer than the data,
  // a length below 2, garbage where a marker belongs.
  refused(std::string("\xFF\xD8\xFF\xDA\x00\x02", 6), "no frame header");
  refused(testing::JpegHeaderDeclaring(64, 0), "DNL");
  std::string runs_past = testing::JpegHeaderDeclaring(64, 48);
  runs_past[4] = '\x7F';  // APP0 length 0x7F10
  refused(runs_past, "past the end");
  std::string short_length = testing::JpegHeaderDeclaring(64, 48);
  short_length[5] = '\x01';
  short_length[4] = '\x00';
  refused(short_length, "length below 2");
  refused(std::string("\xFF\xD8\x12\x34", 4), "expected a marker");
  // A frame header whose component table does not fit its length.
  std::string components = testing::JpegHeaderDeclaring(64, 48, 1);
  components[components.size() - 4] = 5;  // 5 components in a segment sized for 1
  refused(components, "components");
}

TEST(ImageHeaderTest, FrameChecksCompareTheHeaderWithTheIntrinsics) {
  const ImageHeader rgb{ImageFormat::kPng, 128, 96, 3, 8};
  EXPECT_TRUE(CheckFrameImageHeader(rgb, FrameImageRole::kColor, 128, 96, "c").ok());
  const absl::Status mismatch = CheckFrameImageHeader(
      {ImageFormat::kPng, 16384, 16384, 3, 8}, FrameImageRole::kColor, 128, 96, "frame.color");
  EXPECT_EQ(mismatch.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(mismatch.message(),
              AllOf(HasSubstr("frame.color: "), HasSubstr("16384x16384"), HasSubstr("128x96")));
  // Palette and low-bit grey PNGs decode to 8-bit samples; 16-bit colour does not fit.
  EXPECT_TRUE(
      CheckFrameImageHeader({ImageFormat::kPng, 4, 4, 3, 2}, FrameImageRole::kColor, 4, 4, "c")
          .ok());
  EXPECT_THAT(
      CheckFrameImageHeader({ImageFormat::kPng, 4, 4, 3, 16}, FrameImageRole::kColor, 4, 4, "c")
          .message(),
      HasSubstr("8-bit"));
  EXPECT_TRUE(
      CheckFrameImageHeader({ImageFormat::kJpeg, 4, 4, 1, 8}, FrameImageRole::kColor, 4, 4, "c")
          .ok());
  EXPECT_FALSE(
      CheckFrameImageHeader({ImageFormat::kJpeg, 4, 4, 3, 12}, FrameImageRole::kColor, 4, 4, "c")
          .ok());
  // Depth: a 16-bit grey PNG only.
  EXPECT_TRUE(
      CheckFrameImageHeader({ImageFormat::kPng, 4, 4, 1, 16}, FrameImageRole::kDepth, 4, 4, "d")
          .ok());
  for (const ImageHeader& bad :
       {ImageHeader{ImageFormat::kPng, 4, 4, 1, 8}, ImageHeader{ImageFormat::kPng, 4, 4, 2, 16},
        ImageHeader{ImageFormat::kJpeg, 4, 4, 1, 8}}) {
    const absl::Status s = CheckFrameImageHeader(bad, FrameImageRole::kDepth, 4, 4, "frame.depth");
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(s.message(), AllOf(HasSubstr("frame.depth: "), HasSubstr("16-bit")));
  }
}

TEST(ImageHeaderTest, PixelLimitIsResourceExhausted) {
  const int64_t limit = 3840 * 2160;
  EXPECT_TRUE(CheckFramePixels(3840, 2160, limit, "f").ok());
  EXPECT_TRUE(CheckFramePixels(1, limit, limit, "f").ok());
  const absl::Status over = CheckFramePixels(3841, 2160, limit, "frame.intrinsics");
  EXPECT_EQ(over.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(over.message(),
              AllOf(HasSubstr("frame.intrinsics: "), HasSubstr("3841x2160"), HasSubstr("8294400")));
  EXPECT_FALSE(CheckFramePixels(limit + 1, 1, limit, "f").ok());
  // Sides whose product overflows 64 bits are refused, not wrapped around.
  EXPECT_FALSE(CheckFramePixels(int64_t{1} << 40, int64_t{1} << 40, limit, "f").ok());
}

// The buffer decoders only hand PNG and JPEG bytes to OpenCV: a BMP (which imdecode would read)
// is refused by its header and never counted as decoded.
TEST(ImageHeaderTest, BufferDecodersRefuseOtherFormatsBeforeDecoding) {
  const std::string bmp = Encode(cv::Mat(4, 4, CV_8UC3, cv::Scalar(1, 2, 3)), ".bmp");
  const int64_t before = ImageBuffersDecoded();
  absl::StatusOr<cv::Mat> decoded = DecodeColorBuffer(bmp, "frame.color");
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded.status().message(), HasSubstr("not a PNG or JPEG"));
  EXPECT_EQ(ImageBuffersDecoded(), before);
  const std::string png = Encode(cv::Mat(4, 4, CV_8UC3, cv::Scalar(1, 2, 3)), ".png");
  EXPECT_TRUE(DecodeColorBuffer(png, "frame.color").ok());
  EXPECT_EQ(ImageBuffersDecoded(), before + 1);
}

}  // namespace
}  // namespace plx

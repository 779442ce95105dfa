// The Render response size rule shared by the daemon and the CLI: exact for raw encodings, a
// worst case above the raw size for PNG and JPEG, and a refusal that names the size and limit.
#include "proto/render_size.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

namespace pb = ::plenoxd::v1;
using ::testing::HasSubstr;

pb::RenderRequest RequestOf(int width, int height, pb::ColorEncoding color,
                            pb::DepthEncoding depth) {
  pb::RenderRequest request;
  request.mutable_intrinsics()->set_width(width);
  request.mutable_intrinsics()->set_height(height);
  request.set_color_encoding(color);
  request.set_depth_encoding(depth);
  return request;
}

TEST(RenderSizeTest, RawEncodingsAreTheirByteCountsPlusFraming) {
  const int64_t raw = RenderResponseBytesBound(640, 480, pb::COLOR_ENCODING_RAW_RGB8,
                                               pb::DEPTH_ENCODING_RAW_U16);
  EXPECT_GE(raw, 640 * 480 * 5);
  EXPECT_LE(raw, 640 * 480 * 5 + 256) << "framing is a few bytes, not a fraction of the images";
}

TEST(RenderSizeTest, CodecsCountTheirWorstCaseAboveTheRawSize) {
  const int64_t raw = RenderResponseBytesBound(640, 480, pb::COLOR_ENCODING_RAW_RGB8,
                                               pb::DEPTH_ENCODING_RAW_U16);
  const int64_t png = RenderResponseBytesBound(640, 480, pb::COLOR_ENCODING_PNG,
                                               pb::DEPTH_ENCODING_PNG16);
  const int64_t jpeg = RenderResponseBytesBound(640, 480, pb::COLOR_ENCODING_JPEG,
                                                pb::DEPTH_ENCODING_RAW_U16);
  EXPECT_GT(png, raw);
  EXPECT_LT(png, raw * 5 / 4) << "deflate's worst case is the raw size plus about 14 %";
  EXPECT_GT(jpeg, raw - 640 * 480 * 3);
  // The defaults are PNG and PNG16.
  EXPECT_EQ(RenderResponseBytesBound(640, 480, pb::COLOR_ENCODING_UNSPECIFIED,
                                     pb::DEPTH_ENCODING_UNSPECIFIED),
            png);
}

TEST(RenderSizeTest, AResponseOverTheLimitIsRefusedNamingItsSizeAndTheLimit) {
  const pb::RenderRequest request =
      RequestOf(8192, 8192, pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16);
  const int64_t bound = RenderResponseBytesBound(8192, 8192, pb::COLOR_ENCODING_PNG,
                                                 pb::DEPTH_ENCODING_PNG16);
  const absl::Status refused = CheckRenderResponseSize(request, 64 << 20);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_THAT(refused.message(),
              HasSubstr(absl::StrCat("a 8192 x 8192 render with PNG colour and PNG16 depth may "
                                     "take up to ", bound, " bytes, over the largest message of ",
                                     64 << 20, " bytes")));
  EXPECT_TRUE(CheckRenderResponseSize(request, bound).ok());
  EXPECT_TRUE(CheckRenderResponseSize(
                  RequestOf(640, 480, pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16), 64 << 20)
                  .ok());
}

}  // namespace
}  // namespace plx

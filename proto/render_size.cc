#include "proto/render_size.h"

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

namespace pb = ::plenoxd::v1;

// zlib's bound for deflate with any settings (deflateBound when the window or memory level is
// not the default, which OpenCV's PNG writer does not promise to keep), plus the 2-byte header
// and 4-byte Adler-32 of the zlib stream.
int64_t ZlibBound(int64_t n) { return n + (n + 7) / 8 + (n + 63) / 64 + 5 + 6; }

// A PNG of `rows` rows of `row_bytes` bytes each: a filter byte starts every row, the zlib
// stream is cut into IDAT chunks of libpng's 8 KiB buffer (12 bytes of length, type and CRC
// each; counted per 4 KiB to leave room for a smaller buffer), plus the signature, IHDR and IEND
// and a margin for small ancillary chunks.
int64_t PngBound(int64_t rows, int64_t row_bytes) {
  const int64_t zlib = ZlibBound(rows * (1 + row_bytes));
  return zlib + 12 * (zlib / 4096 + 1) + 8 + 25 + 12 + 256;
}

// libjpeg's worst case for 4:2:0 sampling (OpenCV's default for colour): 16-bit coefficients of
// whole 16 x 16 MCUs, 3 bytes per padded pixel (libjpeg-turbo's tj3JPEGBufSize), plus headers
// and tables.
int64_t JpegBound(int64_t width, int64_t height) {
  const auto pad16 = [](int64_t x) { return (x + 15) / 16 * 16; };
  return pad16(width) * pad16(height) * 3 + 2048;
}

int64_t ColorBytes(int64_t width, int64_t height, pb::ColorEncoding encoding) {
  switch (encoding) {
    case pb::COLOR_ENCODING_UNSPECIFIED:
    case pb::COLOR_ENCODING_PNG: return PngBound(height, 3 * width);
    case pb::COLOR_ENCODING_JPEG: return JpegBound(width, height);
    default: return 3 * width * height;  // RAW_RGB8
  }
}

int64_t DepthBytes(int64_t width, int64_t height, pb::DepthEncoding encoding) {
  switch (encoding) {
    case pb::DEPTH_ENCODING_UNSPECIFIED:
    case pb::DEPTH_ENCODING_PNG16: return PngBound(height, 2 * width);
    default: return 2 * width * height;  // RAW_U16
  }
}

const char* ColorName(pb::ColorEncoding encoding) {
  switch (encoding) {
    case pb::COLOR_ENCODING_UNSPECIFIED:
    case pb::COLOR_ENCODING_PNG: return "PNG";
    case pb::COLOR_ENCODING_JPEG: return "JPEG";
    default: return "RAW_RGB8";
  }
}

const char* DepthName(pb::DepthEncoding encoding) {
  switch (encoding) {
    case pb::DEPTH_ENCODING_UNSPECIFIED:
    case pb::DEPTH_ENCODING_PNG16: return "PNG16";
    default: return "RAW_U16";
  }
}

// The response's other fields and the tags and lengths of all of them.
constexpr int64_t kFramingBytes = 128;

}  // namespace

int64_t RenderResponseBytesBound(int64_t width, int64_t height, pb::ColorEncoding color_encoding,
                                 pb::DepthEncoding depth_encoding) {
  return ColorBytes(width, height, color_encoding) + DepthBytes(width, height, depth_encoding) +
         kFramingBytes;
}

absl::Status CheckRenderResponseSize(const pb::RenderRequest& request,
                                     int64_t max_message_bytes) {
  const int64_t width = request.intrinsics().width(), height = request.intrinsics().height();
  const int64_t bytes = RenderResponseBytesBound(width, height, request.color_encoding(),
                                                 request.depth_encoding());
  if (bytes <= max_message_bytes) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      "a ", width, " x ", height, " render with ", ColorName(request.color_encoding()),
      " colour and ", DepthName(request.depth_encoding()), " depth may take up to ", bytes,
      " bytes, over the largest message of ", max_message_bytes, " bytes"));
}

}  // namespace plx

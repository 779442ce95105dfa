// Encoded images as a client sends them (frame.color, frame.depth): the PNG/JPEG header parser
// (core/io/image_header.h), the checks against the intrinsics, then the buffer decoders and the
// conversions to engine images (core/io/image_io.h), in the order the daemon runs them.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "absl/status/statusor.h"
#include "core/io/image_header.h"
#include "core/io/image_io.h"
#include "fuzz/fuzz_util.h"

namespace {

// The daemon decodes only what CheckFramePixels allowed (--max-frame-pixels, 8.3 Mpixel by
// default); a smaller cap here keeps each run fast while the same code paths are reached, and
// stops a header that declares 16384^2 from making OpenCV allocate gigabytes per input.
constexpr int64_t kMaxDecodePixels = int64_t{1} << 18;

void CheckHeader(const plx::ImageHeader& h) {
  // What image_header.h promises of a header it accepted.
  PLX_FUZZ_CHECK(h.width > 0 && h.height > 0, "accepted header has a zero size");
  if (h.format == plx::ImageFormat::kPng) {
    PLX_FUZZ_CHECK(h.channels >= 1 && h.channels <= 4, "PNG channels out of 1..4");
    PLX_FUZZ_CHECK(h.width <= 0x7fffffff && h.height <= 0x7fffffff, "PNG size over 2^31 - 1");
    PLX_FUZZ_CHECK(h.bit_depth == 1 || h.bit_depth == 2 || h.bit_depth == 4 || h.bit_depth == 8 ||
                       h.bit_depth == 16,
                   "PNG bit depth");
  } else {
    // A JPEG frame may have up to 255 components; CheckFrameImageHeader refuses more than 4.
    PLX_FUZZ_CHECK(h.channels >= 1, "JPEG without components");
    PLX_FUZZ_CHECK(h.width <= 65535 && h.height <= 65535, "JPEG size over 65535");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const absl::StatusOr<plx::ImageHeader> header = plx::ReadImageHeader(bytes, "fuzz");
  if (!header.ok()) return 0;
  CheckHeader(*header);
  const int64_t pixels = header->width * header->height;
  if (pixels > kMaxDecodePixels) return 0;
  const int w = static_cast<int>(header->width), h = static_cast<int>(header->height);

  plx::CheckFrameImageHeader(*header, plx::FrameImageRole::kColor, w, h, "c").IgnoreError();
  plx::CheckFrameImageHeader(*header, plx::FrameImageRole::kDepth, w, h, "d").IgnoreError();
  // Both decoders, whatever the checks said: they must refuse (not crash on) an image of the
  // wrong kind too, e.g. a 16-bit PNG given as colour.
  const absl::StatusOr<cv::Mat> color = plx::DecodeColorBuffer(bytes, "c");
  if (color.ok()) {
    PLX_FUZZ_CHECK(color->type() == CV_8UC3, "DecodeColorBuffer gave a non-RGB8 image");
    const plx::ColorImage image = plx::ColorImageFromMat(*color);
    for (float v : image.data) PLX_FUZZ_CHECK(v >= 0.0f && v <= 1.0f, "colour outside [0, 1]");
  }

  const absl::StatusOr<cv::Mat> depth = plx::DecodeDepthBuffer(bytes, "d");
  if (depth.ok()) {
    PLX_FUZZ_CHECK(depth->type() == CV_16UC1, "DecodeDepthBuffer gave a non-uint16 image");
    const plx::DepthImage image = plx::DepthImageFromMat(*depth, 5000.0);
    for (float z : image.data) PLX_FUZZ_CHECK(std::isfinite(z) && z >= 0.0f, "bad depth value");
  }
  return 0;
}

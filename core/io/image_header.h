// What an encoded image says about itself before it is decoded: the PNG IHDR chunk or the JPEG
// frame header (SOFn). A few dozen bytes tell an image's size, so a frame whose image cannot
// fit its intrinsics, or whose size is over a limit, is refused before the codec allocates
// width x height pixels for it (a 1 MB PNG can declare 16384x16384: a decompression bomb).
//
// Only PNG and JPEG are recognised: they are the two encodings the daemon's wire accepts, and
// refusing everything else keeps network bytes away from OpenCV's other codecs.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace plx {

enum class ImageFormat { kPng, kJpeg };
const char* ImageFormatName(ImageFormat format);  // "PNG", "JPEG"

struct ImageHeader {
  ImageFormat format = ImageFormat::kPng;
  int64_t width = 0;  // as declared: PNG up to 2^31 - 1, JPEG up to 65535
  int64_t height = 0;
  // Samples per pixel as stored: PNG grey 1, grey + alpha 2, RGB 3, palette 3 (indices into
  // RGB), RGBA 4; JPEG the frame's component count.
  int channels = 0;
  // Bits per stored sample: PNG 1, 2, 4, 8 or 16 (palette: bits per index); JPEG the sample
  // precision (8 or 12).
  int bit_depth = 0;
};

// Parses the header of a PNG (signature + IHDR) or JPEG (markers up to the first SOFn) held in
// `bytes`; reads nothing past the header and allocates nothing in proportion to the image.
// InvalidArgumentError "<what>: ..." when the bytes are neither, are truncated before the
// header ends, or the header is malformed (zero size, an impossible bit depth).
absl::StatusOr<ImageHeader> ReadImageHeader(absl::string_view bytes, const std::string& what);

// What a frame's image field must hold: colour (PNG or JPEG, 8-bit samples, 1-4 channels) or
// depth (a PNG of 16-bit grey).
enum class FrameImageRole { kColor, kDepth };

// Checks a header against the frame's intrinsics before decoding: the role's format, bit depth
// and channels, and exactly width x height. InvalidArgumentError "<what>: ..." naming the size
// the header declares and the one the intrinsics say.
absl::Status CheckFrameImageHeader(const ImageHeader& header, FrameImageRole role, int width,
                                   int height, const std::string& what);

// A frame of width x height pixels against a per-frame pixel limit: ResourceExhaustedError
// "<what>: a WxH frame is over the limit of M pixels per frame" when over (a limit of the
// service, like a message size, not a malformed request). Non-positive sizes are left to the
// intrinsics' own check.
absl::Status CheckFramePixels(int64_t width, int64_t height, int64_t max_pixels,
                              const std::string& what);

}  // namespace plx

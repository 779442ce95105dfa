// PNG bytes -> cv::Mat with libpng itself, not OpenCV's imdecode: OpenCV lets libpng print its
// errors ("libpng error: IDAT: CRC error") to stderr, outside the daemon's structured log, and
// answers only with an empty image. Here libpng's errors and warnings go to callbacks: an error
// comes back as a Status carrying libpng's reason, and nothing is printed.
#pragma once

#include <string>

#include <opencv2/core.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace plx {

// Decodes a PNG as OpenCV's imdecode(IMREAD_UNCHANGED) does: 16-bit samples stay 16-bit (host
// byte order), others become 8-bit (grey below 8 bits expanded, palettes to colour); grey is
// 1 channel (a tRNS transparency ignored), colour 3 channels in BGR order, 4 (BGRA) with alpha
// (an alpha channel, or tRNS on a colour or palette image; grey + alpha becomes BGRA).
// Decodes whatever size the header declares: callers check the header first (image_header.h).
// InvalidArgumentError "<what>: cannot decode PNG: <libpng's message>" for corrupt or
// truncated data; RESOURCE_EXHAUSTED when libpng runs out of memory (cv::Mat's allocation
// throws std::bad_alloc as elsewhere).
absl::StatusOr<cv::Mat> DecodePng(absl::string_view bytes, const std::string& what);

}  // namespace plx

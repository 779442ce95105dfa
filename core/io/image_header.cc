#include "core/io/image_header.h"

#include <cstddef>

#include "absl/strings/str_cat.h"
#include "core/io/image_io.h"

namespace plx {
namespace {

absl::Status Invalid(const std::string& what, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(what, ": ", message));
}

uint32_t Byte(absl::string_view b, size_t i) { return static_cast<unsigned char>(b[i]); }
uint32_t BigEndian16(absl::string_view b, size_t i) { return Byte(b, i) << 8 | Byte(b, i + 1); }
uint32_t BigEndian32(absl::string_view b, size_t i) {
  return BigEndian16(b, i) << 16 | BigEndian16(b, i + 2);
}

constexpr absl::string_view kPngSignature("\x89PNG\r\n\x1a\n", 8);

// PNG: the 8-byte signature, then the IHDR chunk, which the format requires to come first:
// length (13) | "IHDR" | width | height | bit depth | colour type | compression | filter |
// interlace | CRC. The CRC is left to the decoder, which checks it anyway; a header that lies
// about its size is refused by CheckFrameImageHeader whatever its CRC says.
absl::StatusOr<ImageHeader> ReadPngHeader(absl::string_view b, const std::string& what) {
  constexpr size_t kIhdrEnd = 8 + 8 + 13;
  if (b.size() < kIhdrEnd) return Invalid(what, "PNG truncated before the end of its header");
  if (BigEndian32(b, 8) != 13 || b.substr(12, 4) != "IHDR") {
    return Invalid(what, "PNG without an IHDR chunk first");
  }
  ImageHeader h;
  h.format = ImageFormat::kPng;
  h.width = BigEndian32(b, 16);
  h.height = BigEndian32(b, 20);
  h.bit_depth = static_cast<int>(Byte(b, 24));
  const uint32_t colour_type = Byte(b, 25);
  constexpr int64_t kMaxSide = (int64_t{1} << 31) - 1;  // the PNG specification's bound
  if (h.width == 0 || h.height == 0 || h.width > kMaxSide || h.height > kMaxSide) {
    return Invalid(what,
                   absl::StrCat("PNG header declares an invalid size ", h.width, "x", h.height));
  }
  // The bit depths each colour type allows (PNG specification, table 11.1).
  bool depth_ok = false;
  switch (colour_type) {
    case 0:  // grey
      h.channels = 1;
      depth_ok = h.bit_depth == 1 || h.bit_depth == 2 || h.bit_depth == 4 || h.bit_depth == 8 ||
                 h.bit_depth == 16;
      break;
    case 2:  // RGB
      h.channels = 3;
      depth_ok = h.bit_depth == 8 || h.bit_depth == 16;
      break;
    case 3:  // palette
      h.channels = 3;
      depth_ok = h.bit_depth == 1 || h.bit_depth == 2 || h.bit_depth == 4 || h.bit_depth == 8;
      break;
    case 4:  // grey + alpha
      h.channels = 2;
      depth_ok = h.bit_depth == 8 || h.bit_depth == 16;
      break;
    case 6:  // RGBA
      h.channels = 4;
      depth_ok = h.bit_depth == 8 || h.bit_depth == 16;
      break;
    default:
      return Invalid(what, absl::StrCat("PNG header has an unknown colour type ", colour_type));
  }
  if (!depth_ok) {
    return Invalid(what, absl::StrCat("PNG header has bit depth ", h.bit_depth,
                                      ", impossible for colour type ", colour_type));
  }
  return h;
}

// SOF0-SOF15 carry the frame header, except C4 (DHT), C8 (reserved, JPG) and CC (DAC).
bool IsStartOfFrame(uint32_t marker) {
  return marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
}

// JPEG: SOI (FF D8), then marker segments (FF xx, a 2-byte big-endian length that counts
// itself, the payload) until the frame header SOFn: precision | height | width | components.
// Every length is checked against the bytes left before it is used, and each step moves
// forward, so the walk ends within bytes.size() / 2 steps.
absl::StatusOr<ImageHeader> ReadJpegHeader(absl::string_view b, const std::string& what) {
  size_t pos = 2;  // after SOI
  for (;;) {
    if (pos >= b.size()) return Invalid(what, "JPEG truncated before its frame header");
    if (Byte(b, pos) != 0xFF) {
      return Invalid(what, "JPEG malformed: expected a marker before the frame header");
    }
    while (pos < b.size() && Byte(b, pos) == 0xFF) ++pos;  // fill bytes may pad a marker
    if (pos >= b.size()) return Invalid(what, "JPEG truncated before its frame header");
    const uint32_t marker = Byte(b, pos++);
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no payload
    if (marker == 0x00 || marker == 0xD8 || marker == 0xD9 || marker == 0xDA) {
      // A stuffed zero, a second SOI, the end of the image or a scan: no frame header came.
      return Invalid(what, "JPEG malformed: no frame header (SOF) before the image data");
    }
    if (b.size() - pos < 2) return Invalid(what, "JPEG truncated before its frame header");
    const size_t length = BigEndian16(b, pos);
    if (length < 2) return Invalid(what, "JPEG malformed: a segment length below 2");
    if (length > b.size() - pos) {
      return Invalid(what, "JPEG malformed or truncated: a segment runs past the end");
    }
    if (!IsStartOfFrame(marker)) {
      pos += length;
      continue;
    }
    if (length < 8) return Invalid(what, "JPEG malformed: frame header too short");
    ImageHeader h;
    h.format = ImageFormat::kJpeg;
    h.bit_depth = static_cast<int>(Byte(b, pos + 2));
    h.height = BigEndian16(b, pos + 3);
    h.width = BigEndian16(b, pos + 5);
    h.channels = static_cast<int>(Byte(b, pos + 7));
    // A height of 0 defers it to a DNL marker after the first scan: the size is then unknown
    // until the image is decoded, which is what this check exists to avoid.
    if (h.width == 0 || h.height == 0) {
      return Invalid(what, absl::StrCat("JPEG frame header declares size ", h.width, "x", h.height,
                                        " (a height defined later by DNL is not "
                                        "supported)"));
    }
    if (h.channels == 0 || length < 8 + 3 * static_cast<size_t>(h.channels)) {
      return Invalid(what, "JPEG malformed: frame header components do not fit its length");
    }
    return h;
  }
}

}  // namespace

const char* ImageFormatName(ImageFormat format) {
  return format == ImageFormat::kPng ? "PNG" : "JPEG";
}

absl::StatusOr<ImageHeader> ReadImageHeader(absl::string_view bytes, const std::string& what) {
  if (bytes.empty()) return Invalid(what, "empty image");
  if (bytes.size() >= kPngSignature.size() &&
      bytes.substr(0, kPngSignature.size()) == kPngSignature) {
    return ReadPngHeader(bytes, what);
  }
  if (bytes.size() >= 2 && Byte(bytes, 0) == 0xFF && Byte(bytes, 1) == 0xD8) {
    return ReadJpegHeader(bytes, what);
  }
  return Invalid(what, "not a PNG or JPEG image");
}

absl::Status CheckFrameImageHeader(const ImageHeader& h, FrameImageRole role, int width, int height,
                                   const std::string& what) {
  const std::string described =
      absl::StrCat(ImageFormatName(h.format), " of ", h.channels,
                   h.channels == 1 ? " channel" : " channels", " at ", h.bit_depth, " bits");
  if (role == FrameImageRole::kColor) {
    // PNG grey and palette images below 8 bits are expanded to 8-bit samples when decoded.
    if (h.bit_depth > 8 || h.channels < 1 || h.channels > 4 ||
        (h.format == ImageFormat::kJpeg && h.bit_depth != 8)) {
      return Invalid(what, absl::StrCat("colour images must be 8-bit with 1 to 4 channels, got a ",
                                        described));
    }
  } else if (h.format != ImageFormat::kPng || h.bit_depth != 16 || h.channels != 1) {
    return Invalid(
        what, absl::StrCat("depth images must be 16-bit single-channel PNGs, got a ", described));
  }
  if (h.width != width || h.height != height) {
    return Invalid(
        what, absl::StrCat("image is ", h.width, "x", h.height, " (", ImageFormatName(h.format),
                           " header), the intrinsics say ", SizeString(width, height)));
  }
  return absl::OkStatus();
}

absl::Status CheckFramePixels(int64_t width, int64_t height, int64_t max_pixels,
                              const std::string& what) {
  if (width <= 0 || height <= 0) return absl::OkStatus();
  // Each side first, so the product is only formed when it cannot overflow.
  if (width > max_pixels || height > max_pixels || width * height > max_pixels) {
    return absl::ResourceExhaustedError(absl::StrCat(what, ": a ", width, "x", height,
                                                     " frame is over the limit of ", max_pixels,
                                                     " pixels per frame"));
  }
  return absl::OkStatus();
}

}  // namespace plx

#include "core/io/png_decode.h"

#include <png.h>

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <vector>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// What libpng's callbacks share with the decoder. Plain data only: libpng's errors longjmp
// across the frames that use it, which must not own anything with a destructor.
struct PngSource {
  const unsigned char* data = nullptr;
  size_t size = 0;
  size_t offset = 0;
  char error[256] = {};  // libpng's (or the reader's) message when a step failed
};

// libpng's error callback must not return: the message is kept, then control goes back to the
// setjmp of the step that called libpng.
[[noreturn]] void OnPngError(png_structp png, png_const_charp message) {
  auto* source = static_cast<PngSource*>(png_get_error_ptr(png));
  std::snprintf(source->error, sizeof(source->error), "%s", message);
  png_longjmp(png, 1);
}

// Warnings (an odd ancillary chunk, an sRGB profile libpng dislikes) do not stop the decode,
// and one per frame would flood a log; they are dropped, as the image is still good.
void OnPngWarning(png_structp, png_const_charp) {}

void ReadFromMemory(png_structp png, png_bytep out, size_t length) {
  auto* source = static_cast<PngSource*>(png_get_io_ptr(png));
  if (length > source->size - source->offset) png_error(png, "truncated: the data ends early");
  std::memcpy(out, source->data + source->offset, length);
  source->offset += length;
}

constexpr bool kLittleEndian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

// The decoded image's shape, after the transforms DecodePng asks for.
struct PngShape {
  int width = 0, height = 0, channels = 0, bit_depth = 0;
};

// Reads the header chunks and sets the transforms that give imdecode's layout (see the header).
// False with source->error set when libpng fails. No C++ objects here (longjmp).
bool ReadPngInfo(png_structp png, png_infop info, PngShape* shape) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_info(png, info);
  const int color_type = png_get_color_type(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  const bool colour = (color_type & PNG_COLOR_MASK_COLOR) != 0;
  // PNG is big-endian; the Mat holds host order.
  if (bit_depth == 16 && kLittleEndian) png_set_swap(png);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (!colour && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (colour && png_get_valid(png, info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png);
  if (color_type == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
  if (colour || color_type == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_bgr(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  shape->width = static_cast<int>(png_get_image_width(png, info));
  shape->height = static_cast<int>(png_get_image_height(png, info));
  shape->channels = png_get_channels(png, info);
  shape->bit_depth = png_get_bit_depth(png, info);
  return true;
}

// Decodes every row into `rows` (and checks the rest of the stream). No C++ objects (longjmp).
bool ReadPngRows(png_structp png, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

// Frees libpng's structures whichever way the decode ends.
struct PngReadGuard {
  png_structp png = nullptr;
  png_infop info = nullptr;
  ~PngReadGuard() { png_destroy_read_struct(&png, &info, nullptr); }
};

absl::Status PngError(const std::string& what, const PngSource& source) {
  // libpng's own words for running out of memory.
  if (std::strstr(source.error, "ut of memory") != nullptr) {
    return absl::ResourceExhaustedError(
        absl::StrCat(what, ": cannot decode PNG: out of memory (", source.error, ")"));
  }
  return absl::InvalidArgumentError(absl::StrCat(what, ": cannot decode PNG: ", source.error));
}

}  // namespace

absl::StatusOr<cv::Mat> DecodePng(absl::string_view bytes, const std::string& what) {
  PngSource source;
  source.data = reinterpret_cast<const unsigned char*>(bytes.data());
  source.size = bytes.size();
  PngReadGuard guard;
  guard.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &source, OnPngError, OnPngWarning);
  if (guard.png != nullptr) guard.info = png_create_info_struct(guard.png);
  if (guard.png == nullptr || guard.info == nullptr) {
    return absl::ResourceExhaustedError(absl::StrCat(what, ": cannot decode PNG: out of memory"));
  }
  png_set_read_fn(guard.png, &source, ReadFromMemory);
  PngShape shape;
  if (!ReadPngInfo(guard.png, guard.info, &shape)) return PngError(what, source);
  if (shape.channels < 1 || shape.channels > 4 || (shape.bit_depth != 8 && shape.bit_depth != 16)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": cannot decode PNG: ", shape.channels,
                                                   " channels of ", shape.bit_depth, " bits"));
  }
  cv::Mat image(shape.height, shape.width,
                CV_MAKETYPE(shape.bit_depth == 16 ? CV_16U : CV_8U, shape.channels));
  std::vector<png_bytep> rows(static_cast<size_t>(shape.height));
  for (int v = 0; v < shape.height; ++v) rows[v] = image.ptr<png_byte>(v);
  if (!ReadPngRows(guard.png, rows.data())) return PngError(what, source);
  return image;
}

}  // namespace plx

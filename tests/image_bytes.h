// Hand-built image bytes for the header checks (core/io/image_header.h) and the daemon's
// frame checks: a PNG whose IHDR declares any size over a few bytes of pixel data (the shape of
// a decompression bomb, without its payload: decoding it would allocate the declared size and
// then fail), and a JPEG's frame header behind the segments encoders put first.
#pragma once

#include <cstdint>
#include <string>

namespace plx::testing {

inline void AppendBigEndian32(std::string* out, uint32_t value) {
  for (int shift = 24; shift >= 0; shift -= 8) out->push_back(static_cast<char>(value >> shift));
}

// CRC-32 (ISO-HDLC, as PNG chunks use), bit by bit: these strings are short.
inline uint32_t Crc32(const std::string& bytes) {
  uint32_t crc = 0xFFFFFFFFu;
  for (char c : bytes) {
    crc ^= static_cast<unsigned char>(c);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

inline void AppendPngChunk(std::string* out, const std::string& type, const std::string& data) {
  AppendBigEndian32(out, static_cast<uint32_t>(data.size()));
  const std::string body = type + data;
  out->append(body);
  AppendBigEndian32(out, Crc32(body));
}

// A PNG declaring width x height (colour type 2 = RGB, 0 = grey; bit depth 8 or 16) whose IDAT
// holds one zero byte of zlib data: well formed up to where the pixels run out.
inline std::string PngDeclaring(uint32_t width, uint32_t height, int colour_type = 2,
                                int bit_depth = 8) {
  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string ihdr;
  AppendBigEndian32(&ihdr, width);
  AppendBigEndian32(&ihdr, height);
  ihdr.push_back(static_cast<char>(bit_depth));
  ihdr.push_back(static_cast<char>(colour_type));
  ihdr.append(3, '\0');  // deflate, adaptive filtering, no interlace
  AppendPngChunk(&png, "IHDR", ihdr);
  // zlib header, one final stored block of one zero byte, the Adler-32 of that byte.
  AppendPngChunk(&png, "IDAT", std::string("\x78\x01\x01\x01\x00\xfe\xff\x00\x00\x01\x00\x01", 12));
  AppendPngChunk(&png, "IEND", "");
  return png;
}

// JPEG bytes up to and including a SOF0 frame header for width x height with `components`
// 8-bit components, after an APP0 (JFIF) and a COM segment, each padded by fill bytes.
inline std::string JpegHeaderDeclaring(uint16_t width, uint16_t height, int components = 3) {
  std::string jpeg("\xFF\xD8", 2);
  jpeg += std::string("\xFF\xE0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00", 18);
  jpeg += std::string("\xFF\xFF\xFE\x00\x05hi\x00", 8);  // a fill byte, then COM "hi\0"
  const int length = 8 + 3 * components;
  jpeg += std::string("\xFF\xC0", 2);
  jpeg.push_back(static_cast<char>(length >> 8));
  jpeg.push_back(static_cast<char>(length & 0xFF));
  jpeg.push_back(8);
  jpeg.push_back(static_cast<char>(height >> 8));
  jpeg.push_back(static_cast<char>(height & 0xFF));
  jpeg.push_back(static_cast<char>(width >> 8));
  jpeg.push_back(static_cast<char>(width & 0xFF));
  jpeg.push_back(static_cast<char>(components));
  for (int c = 0; c < components; ++c) {
    jpeg.push_back(static_cast<char>(c + 1));
    jpeg.push_back(0x11);
    jpeg.push_back(0);
  }
  return jpeg;
}

}  // namespace plx::testing

#include "core/io/checksum.h"

#include <array>
#include <bit>
#include <cstring>

namespace plx {
namespace {

// The ECMA-182 polynomial bit-reversed, because the XZ variant processes bits LSB first.
constexpr uint64_t kReflectedPoly = 0xC96C5795D7870F42ull;

// Slice-by-8 tables: tables[0] is the classic byte table; tables[k][b] is the CRC state after
// byte b followed by k zero bytes, which lets the loop fold eight input bytes per step. Plain
// byte-at-a-time CRC runs well below disk speed on gigabyte maps; this is several times faster.
using CrcTables = std::array<std::array<uint64_t, 256>, 8>;

constexpr CrcTables MakeTables() {
  CrcTables t{};
  for (uint64_t b = 0; b < 256; ++b) {
    uint64_t crc = b;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 1) ? (crc >> 1) ^ kReflectedPoly : crc >> 1;
    t[0][b] = crc;
  }
  for (int k = 1; k < 8; ++k) {
    for (int b = 0; b < 256; ++b) t[k][b] = (t[k - 1][b] >> 8) ^ t[0][t[k - 1][b] & 0xff];
  }
  return t;
}

constexpr CrcTables kTables = MakeTables();

// Eight input bytes as the little-endian word the reflected CRC consumes.
uint64_t LoadLittleEndian64(const unsigned char* p) {
  uint64_t word;
  std::memcpy(&word, p, sizeof(word));
  if constexpr (std::endian::native == std::endian::big) {
    uint64_t swapped = 0;
    for (int i = 0; i < 8; ++i) swapped |= ((word >> (8 * i)) & 0xff) << (8 * (7 - i));
    word = swapped;
  }
  return word;
}

}  // namespace

void Crc64::Update(const void* data, size_t size) {
  const auto* p = static_cast<const unsigned char*>(data);
  uint64_t crc = state_;
  while (size >= 8) {
    crc ^= LoadLittleEndian64(p);
    crc = kTables[7][crc & 0xff] ^ kTables[6][(crc >> 8) & 0xff] ^
          kTables[5][(crc >> 16) & 0xff] ^ kTables[4][(crc >> 24) & 0xff] ^
          kTables[3][(crc >> 32) & 0xff] ^ kTables[2][(crc >> 40) & 0xff] ^
          kTables[1][(crc >> 48) & 0xff] ^ kTables[0][crc >> 56];
    p += 8;
    size -= 8;
  }
  for (; size > 0; --size, ++p) crc = kTables[0][(crc ^ *p) & 0xff] ^ (crc >> 8);
  state_ = crc;
}

uint64_t Crc64Of(const void* data, size_t size) {
  Crc64 crc;
  crc.Update(data, size);
  return crc.value();
}

}  // namespace plx

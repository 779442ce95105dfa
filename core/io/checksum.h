// CRC-64 for map files (core/formats/map_file.h): detects torn writes, truncation that happens to
// land on a plausible size, and bit rot in multi-gigabyte payloads.
//
// Variant: CRC-64/XZ (ECMA-182 polynomial 0x42F0E1EBA9EA3693, reflected, initial value and final
// xor all ones). Its published check value, the CRC of the nine ASCII bytes "123456789", is
// 0x995DC9BBDF1939FA, so other tools (xz, Python's crcmod) can verify a map file's trailer.
#pragma once

#include <cstddef>
#include <cstdint>

namespace plx {

// Incremental CRC-64/XZ: feed the bytes in any number of pieces; value() is the CRC of all
// bytes fed so far (and may be read at any point without disturbing the state).
class Crc64 {
 public:
  void Update(const void* data, size_t size);
  uint64_t value() const { return ~state_; }

 private:
  uint64_t state_ = ~uint64_t{0};
};

// CRC-64/XZ of one buffer.
uint64_t Crc64Of(const void* data, size_t size);

}  // namespace plx

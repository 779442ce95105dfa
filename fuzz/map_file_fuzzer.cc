// Map files (core/formats/map_file.h) as LoadMap and ReadMapInfo read them from disk: the daemon
// loads every <name>.plx of its data dir at start and on LoadMap, so a file may be truncated,
// corrupt or hostile.
//
// Input: one mode byte, then file bytes.
//   mode bit 0 clear: the bytes are the whole file, as they are. Almost all such inputs stop
//     at the CRC-64 check, which covers the header parser and the size checks before it.
//   mode bit 0 set: the harness completes the file the way a writer would, so the fuzzer
//     reaches what comes after the checksum (brick table, duplicates, index bounds, the grid):
//     when the header's brick count N is small, a short file is padded with zero payload to the
//     size N bricks need, and the correct CRC-64 trailer is appended. The seeds of this mode are
//     SaveMap output with the payload and trailer cut off (fuzz/make_seeds.cc), a few hundred
//     bytes instead of 57 KB per brick; in format version 2 the keyframe section comes before
//     the payload, so those seeds keep it and the fuzzer reaches its decoder.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/formats/map_file.h"
#include "core/io/checksum.h"
#include "fuzz/fuzz_util.h"

namespace {

// The layout of map_file.h, restated here only to find the brick count and where the table
// and the payload start.
constexpr size_t kVersionOffset = 8;
constexpr size_t kSourceLengthOffset = 76;
constexpr size_t kHeaderBytesWithoutSource = 88;
constexpr size_t kVersion2ExtraBytes = 20;  // map version, keyframe count, section size
constexpr size_t kBytesPerBrick = 12 + 4 * 512 * (1 + 27);
// Padding is written to disk on every run; more bricks would only slow the fuzzer down.
constexpr uint64_t kMaxPaddedBricks = 8;
// LoadMap may build a coarse index of up to 2^27 entries (1 GiB; map_file_test covers the cap):
// the header's bounds, grown to cover every brick of the table. Such files are skipped, so a run
// takes milliseconds rather than seconds of memset (and never nears libFuzzer's -timeout);
// smaller indexes go through the same code.
constexpr size_t kIndexMinOffset = 52;
constexpr int64_t kMaxIndexEntries = int64_t{1} << 20;

uint64_t LoadLe(const std::string& bytes, size_t offset, int width) {
  uint64_t value = 0;
  for (int i = 0; i < width; ++i) {
    value |= uint64_t{static_cast<uint8_t>(bytes[offset + i])} << (8 * i);
  }
  return value;
}

int32_t LoadI32(const std::string& bytes, size_t offset) {
  return static_cast<int32_t>(static_cast<uint32_t>(LoadLe(bytes, offset, 4)));
}

// The header's size as the version field and source length say (0 when too short to say).
size_t HeaderBytes(const std::string& file) {
  if (file.size() < kHeaderBytesWithoutSource) return 0;
  const size_t extra = LoadLe(file, kVersionOffset, 4) >= 2 ? kVersion2ExtraBytes : 0;
  return kHeaderBytesWithoutSource + LoadLe(file, kSourceLengthOffset, 4) + extra;
}

// An upper bound of the index entries LoadMap would allocate for `file` (0 when the header is
// too short to say): the box of the header's index bounds and every brick of the table that
// is present, plus the grid's growth margin.
int64_t IndexEntriesAfterLoading(const std::string& file) {
  if (file.size() < kHeaderBytesWithoutSource) return 0;
  int64_t lo[3], hi[3];
  bool empty = false;
  for (int a = 0; a < 3; ++a) {
    lo[a] = LoadI32(file, kIndexMinOffset + 4 * a);
    const int64_t dims = LoadI32(file, kIndexMinOffset + 12 + 4 * a);
    hi[a] = lo[a] + dims - 1;
    empty = empty || dims <= 0;
  }
  const size_t table = HeaderBytes(file);
  for (size_t at = table; at + 12 <= file.size() && at < table + 12 * kMaxPaddedBricks; at += 12) {
    for (int a = 0; a < 3; ++a) {
      const int64_t c = LoadI32(file, at + 4 * a);
      lo[a] = empty ? c : std::min(lo[a], c);
      hi[a] = empty ? c : std::max(hi[a], c);
    }
    empty = false;
  }
  if (empty) return 0;
  int64_t entries = 1;
  for (int a = 0; a < 3; ++a) {
    entries *= std::clamp<int64_t>(hi[a] - lo[a] + 1 + 2 * plx::SparseGrid::kIndexGrowthMargin, 1,
                                   kMaxIndexEntries + 1);
    entries = std::min(entries, kMaxIndexEntries + 1);
  }
  return entries;
}

std::string CompleteFile(std::string file) {
  if (file.size() >= kHeaderBytesWithoutSource) {
    const size_t source_bytes = LoadLe(file, kSourceLengthOffset, 4);
    const size_t header_bytes = HeaderBytes(file);
    if (source_bytes <= plx::kMaxMapSourceBytes && file.size() >= header_bytes) {
      const size_t count_at = kHeaderBytesWithoutSource + source_bytes - 8;
      const uint64_t bricks = LoadLe(file, count_at, 8);
      // Version 2: the keyframe section (before the payload) is the input's own.
      const uint64_t section =
          header_bytes > kHeaderBytesWithoutSource + source_bytes ? LoadLe(file, count_at + 20, 8)
                                                                  : 0;
      if (bricks <= kMaxPaddedBricks && section <= file.size()) {
        const size_t needed = header_bytes + bricks * kBytesPerBrick + section;
        if (file.size() < needed) file.resize(needed, '\0');
      }
    }
  }
  const uint64_t crc = plx::Crc64Of(file.data(), file.size());
  for (int i = 0; i < 8; ++i) file.push_back(static_cast<char>(crc >> (8 * i)));
  return file;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  std::string file(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1) file = CompleteFile(std::move(file));
  // After completing: the padding can finish a brick entry the input only began.
  if (IndexEntriesAfterLoading(file) > kMaxIndexEntries) return 0;
  const std::string path = plx::fuzz::ScratchPath("in.plx");
  plx::fuzz::WriteFileOrDie(path, file);

  const absl::StatusOr<plx::MapFileInfo> info = plx::ReadMapInfo(path);
  absl::StatusOr<plx::LoadedMapFile> map = plx::LoadMapFile(path);
  if (!map.ok()) return 0;
  // LoadMapFile validates everything ReadMapInfo does, and more.
  PLX_FUZZ_CHECK(info.ok(), "LoadMapFile accepted a file ReadMapInfo refused");
  PLX_FUZZ_CHECK(map->map->grid.num_bricks() == info->bricks, "brick count");
  PLX_FUZZ_CHECK(static_cast<int64_t>(map->state.keyframes.size()) == info->keyframes,
                 "keyframe count");

  // A map that loads must save, and load again the same (the daemon saves what it loaded; a
  // save it cannot read back would lose the map at the next restart).
  const std::string again = plx::fuzz::ScratchPath("again.plx");
  const absl::Status saved = plx::SaveMap(*map->map, map->state, again);
  PLX_FUZZ_CHECK(saved.ok(), saved.ToString());
  // Only the brick table and the state are kept, so two grids are never held at once.
  const std::vector<plx::BrickCoord> bricks = map->map->grid.brick_coords();
  const plx::MapFileState state = std::move(map->state);
  map->map.reset();
  absl::StatusOr<plx::LoadedMapFile> reloaded = plx::LoadMapFile(again);
  PLX_FUZZ_CHECK(reloaded.ok(), reloaded.status().ToString());
  PLX_FUZZ_CHECK(reloaded->map->grid.brick_coords() == bricks, "brick table after a round trip");
  PLX_FUZZ_CHECK(reloaded->state.map_version == state.map_version, "map version");
  PLX_FUZZ_CHECK(reloaded->state.keyframes.size() == state.keyframes.size(), "keyframes");
  for (size_t i = 0; i < state.keyframes.size(); ++i) {
    const plx::MapKeyframe& a = state.keyframes[i];
    const plx::MapKeyframe& b = reloaded->state.keyframes[i];
    PLX_FUZZ_CHECK((a.features == nullptr) == (b.features == nullptr), "features flag");
    PLX_FUZZ_CHECK(a.features == nullptr || a.features->descriptors == b.features->descriptors,
                   "descriptors after a round trip");
  }
  return 0;
}

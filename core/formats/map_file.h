// Map files (DESIGN.md §5): a PlenoxelMap on disk, bit-exact, versioned and checksummed, and
// (format version 2) what SLAM needs to continue the map: its keyframes and the version number
// the saving daemon had given it.
//
// Layout. Every number is little-endian; floats are IEEE-754 binary32. Each field is written on
// its own (never a memcpy of a struct), so padding and compiler layout never reach the file.
//
//   offset    size      field
//   0         8         magic "PLXMAP\r\n" (the \r\n shows up mangled after a text-mode copy)
//   8         4         u32  format version (1 or 2)
//   12        4         u32  header size H: 88 + L (version 1), 108 + L (version 2)
//   16        4         f32  voxel size, metres (finite, > 0)
//   20        4         f32  render.step_voxels
//   24        4         f32  render.sigma_threshold
//   28        4         f32  render.stop_transmittance
//   32        4         f32  render.near
//   36        4         f32  render.far
//   40        12        f32  render.background[3]
//   52        12        i32  index_min[3]   coarse index origin, in bricks (informational, below)
//   64        12        i32  index_dims[3]  coarse index size, in bricks
//   76        4         u32  L = source text length (at most kMaxMapSourceBytes)
//   80        L         source text, raw bytes (no terminator)
//   80+L      8         u64  N = brick count
//   version 2 only:
//   88+L      8         u64  the map's version number when it was saved (0: none given)
//   96+L      4         u32  K = keyframe count
//   100+L     8         u64  S = keyframe section size, bytes
//   all versions:
//   H         12 N      brick table: i32 x, y, z per brick, in slot order
//   H+12N     S         version 2: the keyframe section (core/formats/map_keyframes_codec.h);
//                       S = 0 in version 1
//   H+12N+S   2048 N    density payload: f32 [N * 512], slot-major, as SparseGrid stores it
//   ...       55296 N   SH payload: f32 [N * 512 * 27], as SparseGrid stores it
//   end-8     8         u64  CRC-64/XZ (core/io/checksum.h) of every preceding byte
//
// A file is therefore exactly H + 57356 N + S + 8 bytes; readers check that before allocating.
// The keyframe section sits before the payload so that its damage is found before gigabytes of
// grid are read.
//
// Versions: version 2 (this build's) added the map's version number and keyframes; the writer
// uses it only when it has either (SaveMap with a MapFileState), so a map without them is still
// written as version 1 and opens in older builds. Both versions load; a version-1 file has no
// keyframes and version number 0.
//
// Brick coordinates are absolute (brick b holds world vertices 8b .. 8b+7), so the brick table
// alone places the map in the world. index_min/index_dims are the saved grid's coarse index
// bounds (its GridView origin is index_min * 8 * voxel_size); the loader restores them before
// allocating the bricks in table order, so payloads, slots and renders come back bit-identical.

// Saving writes "<path>.tmp.<pid>" in the same directory, fsyncs it and renames it over `path`,
// so readers only ever see the old file or the complete new one. Concurrent saves to the same
// path from one process are not supported (they share the temp name).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/formats/map_keyframe.h"
#include "core/grid/plenoxel_map.h"
#include "core/grid/render_options.h"

namespace plx {

inline constexpr char kMapFileMagic[8] = {'P', 'L', 'X', 'M', 'A', 'P', '\r', '\n'};
// The newest format version (what this build writes when it has keyframes or a version number)
// and the oldest one it reads.
inline constexpr uint32_t kMapFileVersion = 2;
inline constexpr uint32_t kOldestMapFileVersion = 1;
// Caps the source text so a corrupt length cannot make the reader allocate much.
inline constexpr uint32_t kMaxMapSourceBytes = 64 * 1024;

// What the header says, read without touching the payload (tools list maps with it).
struct MapFileInfo {
  uint32_t version = 0;
  float voxel_size = 0.0f;
  int64_t bricks = 0;
  int64_t bytes = 0;  // file size
  std::string source;
  RenderOptions render;
  std::array<int32_t, 3> index_min = {0, 0, 0};
  std::array<int32_t, 3> index_dims = {0, 0, 0};
  uint64_t map_version = 0;     // version 2: the map's version number when saved
  int64_t keyframes = 0;        // version 2: keyframes in the file
  int64_t keyframe_bytes = 0;   // version 2: the keyframe section's size (S)
};

// What a map file holds besides the grid (format version 2; empty for version-1 files).
struct MapFileState {
  // The map's version number when it was saved (the daemon's, so a restarted one carries the
  // numbering on); 0: none.
  uint64_t map_version = 0;
  MapKeyframes keyframes;  // in the order the map accepted them
  bool empty() const { return map_version == 0 && keyframes.empty(); }
};

// Writes `map` to `path` atomically (temp file, fsync, rename). NotFound when the directory does
// not exist (it is not created); InvalidArgument for a map LoadMap would refuse (the same checks
// run on both sides, so whatever SaveMap writes LoadMap reads); ResourceExhausted when out of
// memory or disk. Failures name the path and the system's reason, and leave any previous file at
// `path` untouched and no temp file behind.
absl::Status SaveMap(const PlenoxelMap& map, const std::string& path);
// The same with `state`: format version 2 unless the state is empty (then version 1). Keyframes
// CheckStorableKeyframe refuses fail the save with InvalidArgument naming the keyframe.
absl::Status SaveMap(const PlenoxelMap& map, const MapFileState& state, const std::string& path);

struct LoadMapOptions {
  // A map whose grid would need more memory than this (SparseGrid::EstimateMemory of the
  // header's brick count and index size) is refused with ResourceExhausted before anything is
  // allocated or the payload is read. 0: no limit.
  int64_t max_memory_bytes = 0;
};

// Reads a map file written by SaveMap. Only regular files are opened (never blocking on a FIFO).
// Errors name the file: NotFound (missing), InvalidArgument (not a regular file, not a map file),
// Unimplemented (a format version other than 1 and 2), DataLoss (truncated, inconsistent sizes,
// bad voxel size, checksum mismatch, duplicate bricks, bricks outside the world extent, a bad
// keyframe), ResourceExhausted (over options.max_memory_bytes, or out of memory). The checksum is
// verified before the grid is built; no allocation exceeds what the file's actual size can back.
absl::StatusOr<std::unique_ptr<PlenoxelMap>> LoadMap(const std::string& path,
                                                     const LoadMapOptions& options = {});

// A map file's grid and state.
struct LoadedMapFile {
  std::unique_ptr<PlenoxelMap> map;
  MapFileState state;
};
// LoadMap that also returns the state (keyframes, version number; empty for version 1). A
// damaged keyframe section is DataLoss like any other damage, and is found before the grid is
// built.
absl::StatusOr<LoadedMapFile> LoadMapFile(const std::string& path,
                                          const LoadMapOptions& options = {});

// Reads and validates the header only, including that the file size matches the brick count
// (and, version 2, the keyframe section's size). Does not verify the checksum (that needs the
// whole file; LoadMap does it).
absl::StatusOr<MapFileInfo> ReadMapInfo(const std::string& path);

}  // namespace plx

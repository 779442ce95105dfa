#include "core/formats/map_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/formats/map_keyframes_codec.h"
#include "core/io/atomic_write.h"
#include "core/io/checksum.h"

namespace plx {
namespace {

// Sizes of the layout documented in map_file.h.
constexpr int64_t kMagicBytes = 8;
constexpr int64_t kFixedHeaderBytes = 80;          // magic .. source length
constexpr int64_t kHeaderBytesWithoutSource = 88;  // plus the brick count (version 1)
// Version 2's header adds the map's version number, the keyframe count and the section's size.
constexpr int64_t kVersion2HeaderExtraBytes = 8 + 4 + 8;
constexpr int64_t kChecksumBytes = 8;
constexpr int64_t kMinimalFileBytes = kHeaderBytesWithoutSource + kChecksumBytes;
constexpr int64_t kTableBytesPerBrick = 3 * sizeof(int32_t);
constexpr int64_t kDensityFloatsPerBrick = kBrickVertices;
constexpr int64_t kShFloatsPerBrick = int64_t{kBrickVertices} * kShCoeffCount;
constexpr int64_t kBytesPerBrick =
    kTableBytesPerBrick + (kDensityFloatsPerBrick + kShFloatsPerBrick) * sizeof(float);
// SparseGrid addresses vertices with int32 slots; a larger count can only be corruption.
constexpr int64_t kMaxBricks = std::numeric_limits<int32_t>::max() / kBrickVertices;
// Streaming granularity: large enough for full-speed I/O, small enough to never matter.
constexpr size_t kIoChunkBytes = size_t{1} << 20;

static_assert(sizeof(float) == 4 && std::numeric_limits<float>::is_iec559,
              "map files store IEEE-754 binary32");

// ---------------------------------------------------------------------------------------------
// Little-endian field encoding, independent of the host's byte order.

void StoreLe(uint64_t value, int bytes, uint8_t* out) {
  for (int i = 0; i < bytes; ++i) out[i] = static_cast<uint8_t>(value >> (8 * i));
}

uint64_t LoadLe(const uint8_t* in, int bytes) {
  uint64_t value = 0;
  for (int i = 0; i < bytes; ++i) value |= uint64_t{in[i]} << (8 * i);
  return value;
}

uint32_t LoadU32(const uint8_t* in) { return static_cast<uint32_t>(LoadLe(in, 4)); }
int32_t LoadI32(const uint8_t* in) { return static_cast<int32_t>(LoadU32(in)); }
float LoadF32(const uint8_t* in) { return std::bit_cast<float>(LoadU32(in)); }

uint32_t ByteSwap32(uint32_t v) {
  return (v >> 24) | ((v >> 8) & 0xff00u) | ((v << 8) & 0xff0000u) | (v << 24);
}

// ---------------------------------------------------------------------------------------------
// POSIX helpers. Errors carry the system's reason via absl::ErrnoToStatus ("message: reason").

// Callers copy errno into a local first: building the message allocates, and library calls may
// change errno even when they succeed.
absl::Status ErrnoError(int error_number, const std::string& message) {
  return absl::ErrnoToStatus(error_number, message);
}

class ScopedFd {
 public:
  explicit ScopedFd(int fd = -1) : fd_(fd) {}
  ScopedFd(ScopedFd&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  ScopedFd& operator=(ScopedFd&& other) noexcept {
    std::swap(fd_, other.fd_);
    return *this;
  }
  ~ScopedFd() {
    if (fd_ >= 0) ::close(fd_);
  }
  int get() const { return fd_; }
  // Closes now and reports close's own error: on some file systems a failed write only
  // surfaces here.
  int Close() { return ::close(std::exchange(fd_, -1)); }

 private:
  int fd_;
};

// ---------------------------------------------------------------------------------------------
// Reading.

struct OpenedFile {
  ScopedFd fd;
  int64_t size = 0;
};

// What a file that is not a regular one is, for the error message.
const char* FileTypeName(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISCHR(mode) || S_ISBLK(mode)) return "a device";
  return "not a regular file";
}

absl::StatusOr<OpenedFile> OpenForRead(const std::string& path) {
  OpenedFile file;
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer, for ever, and
  // with it every later load and save on the daemon's file worker. The mode is checked right
  // after; for a regular file O_NONBLOCK changes nothing.
  file.fd = ScopedFd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (file.fd.get() < 0) {
    const int err = errno;
    return ErrnoError(err, absl::StrCat("cannot open map file ", path));
  }
  struct stat st;
  if (::fstat(file.fd.get(), &st) != 0) {
    const int err = errno;
    return ErrnoError(err, absl::StrCat("cannot stat ", path));
  }
  // Only regular files are read: a directory would read as a zero-byte "truncated map", a FIFO
  // or a device could block any read.
  if (!S_ISREG(st.st_mode)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a regular file (",
                                                   FileTypeName(st.st_mode), ")"));
  }
  file.size = static_cast<int64_t>(st.st_size);
  return file;
}

// Reads exactly `size` bytes at `offset`. Sizes were checked against fstat first, so running
// out of file here means it shrank underneath us.
absl::Status ReadExactAt(int fd, int64_t offset, void* dst, size_t size, const std::string& path) {
  auto* out = static_cast<uint8_t*>(dst);
  while (size > 0) {
    const ssize_t got = ::pread(fd, out, std::min(size, kIoChunkBytes), offset);
    if (got < 0) {
      const int err = errno;
      if (err == EINTR) continue;
      return ErrnoError(err, absl::StrCat("cannot read map file ", path));
    }
    if (got == 0) {
      return absl::DataLossError(absl::StrCat(path, ": file shrank while it was being read"));
    }
    out += got;
    offset += got;
    size -= static_cast<size_t>(got);
  }
  return absl::OkStatus();
}

// Reads `count` little-endian float32 straight into their destination (no staging copy, so a
// multi-gigabyte map is never held twice).
absl::Status ReadFloatsAt(int fd, int64_t offset, float* dst, size_t count,
                          const std::string& path) {
  PLX_RETURN_IF_ERROR(ReadExactAt(fd, offset, dst, count * sizeof(float), path));
  if constexpr (std::endian::native == std::endian::big) {
    for (size_t i = 0; i < count; ++i) {
      dst[i] = std::bit_cast<float>(ByteSwap32(std::bit_cast<uint32_t>(dst[i])));
    }
  }
  return absl::OkStatus();
}

// `expected` says what the file should have held, e.g. "at least 96 bytes".
absl::Status TruncatedError(const std::string& path, const std::string& expected, int64_t actual) {
  return absl::DataLossError(
      absl::StrCat(path, ": file is truncated: expected ", expected, ", found ", actual));
}

std::string AtLeast(int64_t bytes) { return absl::StrCat("at least ", bytes, " bytes"); }

struct ParsedHeader {
  MapFileInfo info;
  int64_t header_bytes = 0;  // offset of the brick table
  // Where the keyframe section and the density payload start.
  int64_t keyframes_offset() const { return header_bytes + info.bricks * kTableBytesPerBrick; }
  int64_t payload_offset() const { return keyframes_offset() + info.keyframe_bytes; }
};

int64_t HeaderBytes(uint32_t version, int64_t source_bytes) {
  return kHeaderBytesWithoutSource + source_bytes + (version >= 2 ? kVersion2HeaderExtraBytes : 0);
}

// Validates everything the header claims against the file's real size, so nothing later
// allocates from an unchecked count.
absl::StatusOr<ParsedHeader> ReadHeader(const OpenedFile& file, const std::string& path) {
  const int64_t size = file.size;
  uint8_t fixed[kFixedHeaderBytes];
  const int64_t got = std::min(size, kFixedHeaderBytes);
  PLX_RETURN_IF_ERROR(ReadExactAt(file.fd.get(), 0, fixed, static_cast<size_t>(got), path));

  // A file shorter than the magic still counts as a (truncated) map when what is there matches.
  if (std::memcmp(fixed, kMapFileMagic, static_cast<size_t>(std::min(got, kMagicBytes))) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a plenoxd map file"));
  }
  if (size < 12) return TruncatedError(path, AtLeast(kMinimalFileBytes), size);
  // The version comes before any other field: a later version may lay out the rest differently.
  const uint32_t version = LoadU32(fixed + 8);
  if (version < kOldestMapFileVersion || version > kMapFileVersion) {
    return absl::UnimplementedError(absl::StrCat(
        path, ": map format version ", version, " is not supported; this build reads versions ",
        kOldestMapFileVersion, " to ", kMapFileVersion));
  }
  if (size < kFixedHeaderBytes) return TruncatedError(path, AtLeast(kMinimalFileBytes), size);

  ParsedHeader h;
  MapFileInfo& info = h.info;
  info.version = version;
  info.bytes = size;
  const uint32_t header_size_field = LoadU32(fixed + 12);
  info.voxel_size = LoadF32(fixed + 16);
  info.render.step_voxels = LoadF32(fixed + 20);
  info.render.sigma_threshold = LoadF32(fixed + 24);
  info.render.stop_transmittance = LoadF32(fixed + 28);
  info.render.near = LoadF32(fixed + 32);
  info.render.far = LoadF32(fixed + 36);
  for (int c = 0; c < 3; ++c) info.render.background[c] = LoadF32(fixed + 40 + 4 * c);
  for (int a = 0; a < 3; ++a) {
    info.index_min[a] = LoadI32(fixed + 52 + 4 * a);
    info.index_dims[a] = LoadI32(fixed + 64 + 4 * a);
  }
  const uint32_t source_bytes = LoadU32(fixed + 76);

  if (!std::isfinite(info.voxel_size) || info.voxel_size <= 0.0f) {
    return absl::DataLossError(absl::StrCat(
        path, ": voxel size ", info.voxel_size,
        " is not a positive finite number; the file is corrupt"));
  }
  for (int a = 0; a < 3; ++a) {
    if (info.index_dims[a] < 0) {
      return absl::DataLossError(absl::StrCat(path, ": negative index size ", info.index_dims[a],
                                              "; the header is corrupt"));
    }
  }
  if (source_bytes > kMaxMapSourceBytes) {
    return absl::DataLossError(absl::StrCat(path, ": source text length ", source_bytes,
                                            " exceeds the limit of ", kMaxMapSourceBytes,
                                            " bytes; the header is corrupt"));
  }
  h.header_bytes = HeaderBytes(version, source_bytes);
  if (header_size_field != h.header_bytes) {
    return absl::DataLossError(absl::StrCat(
        path, ": header size field says ", header_size_field, " bytes but a version-", version,
        " header with ", source_bytes, " bytes of source text has ", h.header_bytes,
        "; the header is corrupt"));
  }
  if (size < h.header_bytes + kChecksumBytes) {
    return TruncatedError(path, AtLeast(h.header_bytes + kChecksumBytes), size);
  }

  std::vector<uint8_t> rest(static_cast<size_t>(h.header_bytes - kFixedHeaderBytes));
  PLX_RETURN_IF_ERROR(
      ReadExactAt(file.fd.get(), kFixedHeaderBytes, rest.data(), rest.size(), path));
  info.source.assign(reinterpret_cast<const char*>(rest.data()), source_bytes);
  const uint8_t* after_source = rest.data() + source_bytes;
  const uint64_t bricks = LoadLe(after_source, 8);
  uint64_t keyframe_bytes = 0;
  if (version >= 2) {
    info.map_version = LoadLe(after_source + 8, 8);
    info.keyframes = LoadU32(after_source + 16);
    keyframe_bytes = LoadLe(after_source + 20, 8);
    // Checked before it is added to anything: a flipped high bit must not wrap a size.
    if (keyframe_bytes > static_cast<uint64_t>(size)) {
      return TruncatedError(
          path, absl::StrCat("at least ", keyframe_bytes, " bytes for its keyframe section"),
          size);
    }
    info.keyframe_bytes = static_cast<int64_t>(keyframe_bytes);
    if (info.keyframes > info.keyframe_bytes / kMapKeyframeFixedBytes) {
      return absl::DataLossError(
          absl::StrCat(path, ": ", info.keyframes, " keyframes cannot fit in a section of ",
                       info.keyframe_bytes, " bytes; the header is corrupt"));
    }
  }

  // Checked before anything is sized from it: a flipped high bit must not become a huge vector.
  if (bricks > static_cast<uint64_t>(kMaxBricks)) {
    return absl::DataLossError(absl::StrCat(path, ": brick count ", bricks,
                                            " exceeds the limit of ", kMaxBricks,
                                            " bricks and cannot match the file size of ", size,
                                            " bytes; the header is corrupt"));
  }
  info.bricks = static_cast<int64_t>(bricks);
  const int64_t expected =
      h.header_bytes + info.bricks * kBytesPerBrick + info.keyframe_bytes + kChecksumBytes;
  // Version 2 names the keyframe section too: its size is the header's other claim.
  const std::string keyframes =
      version >= 2 ? absl::StrCat(" and ", info.keyframe_bytes, " bytes of keyframes") : "";
  if (size < expected) {
    return TruncatedError(
        path, absl::StrCat(expected, " bytes for ", info.bricks, " bricks", keyframes), size);
  }
  if (size > expected) {
    return absl::DataLossError(absl::StrCat(
        path, ": brick count ", info.bricks, keyframes, " is inconsistent with the file size: ",
        info.bricks, " bricks", keyframes, " need ", expected, " bytes, the file has ", size));
  }
  return h;
}

// Recomputes the CRC of everything before the trailer. Done before the grid is built so a
// corrupt file is reported as corrupt rather than as whatever odd value it happens to contain.
absl::Status VerifyChecksum(const OpenedFile& file, const std::string& path) {
  const int64_t covered = file.size - kChecksumBytes;
  std::vector<uint8_t> buffer(std::min<int64_t>(covered, kIoChunkBytes));
  Crc64 crc;
  for (int64_t offset = 0; offset < covered;) {
    const size_t n = static_cast<size_t>(std::min<int64_t>(covered - offset, buffer.size()));
    PLX_RETURN_IF_ERROR(ReadExactAt(file.fd.get(), offset, buffer.data(), n, path));
    crc.Update(buffer.data(), n);
    offset += static_cast<int64_t>(n);
  }
  uint8_t trailer[kChecksumBytes];
  PLX_RETURN_IF_ERROR(ReadExactAt(file.fd.get(), covered, trailer, sizeof(trailer), path));
  if (LoadLe(trailer, 8) != crc.value()) {
    return absl::DataLossError(absl::StrCat(path, ": checksum mismatch, the file is corrupt"));
  }
  return absl::OkStatus();
}

// AllocateBricks would silently merge duplicates and shift every later slot, so the payload
// would land in the wrong bricks; refuse instead.
absl::Status CheckNoDuplicateBricks(const std::vector<BrickCoord>& bricks) {
  absl::flat_hash_map<BrickCoord, int64_t> first_entry;
  first_entry.reserve(bricks.size());
  for (int64_t i = 0; i < static_cast<int64_t>(bricks.size()); ++i) {
    const auto [it, inserted] = first_entry.emplace(bricks[i], i);
    if (!inserted) {
      const BrickCoord& b = bricks[i];
      return absl::InvalidArgumentError(absl::StrCat("brick (", b.x, ", ", b.y, ", ", b.z,
                                                     ") appears twice in the brick table "
                                                     "(entries ", it->second, " and ", i, ")"));
    }
  }
  return absl::OkStatus();
}

// What a map must satisfy to be stored, checked by both sides: LoadMap refuses to build, and
// SaveMap to write, a map that breaks any of it, so a file SaveMap wrote is a file LoadMap reads.
// The message names no file; callers prefix the path.
absl::Status CheckStorableMap(float voxel_size, size_t source_bytes,
                              const std::array<int32_t, 3>& index_min,
                              const std::array<int32_t, 3>& index_dims,
                              const std::vector<BrickCoord>& bricks) {
  if (!std::isfinite(voxel_size) || voxel_size <= 0.0f) {
    return absl::InvalidArgumentError(
        absl::StrCat("voxel size ", voxel_size, " is not a positive finite number"));
  }
  if (source_bytes > kMaxMapSourceBytes) {
    return absl::InvalidArgumentError(absl::StrCat("source text is ", source_bytes,
                                                   " bytes, the limit is ", kMaxMapSourceBytes));
  }
  if (static_cast<int64_t>(bricks.size()) > kMaxBricks) {
    return absl::InvalidArgumentError(
        absl::StrCat(bricks.size(), " bricks exceed the limit of ", kMaxBricks));
  }
  // Inside the world (core/common/world_extent.h): the grid's coordinates cannot wrap.
  PLX_RETURN_IF_ERROR(
      SparseGrid::CheckIndexBoundsInsideWorld(index_min, index_dims, voxel_size));
  for (const BrickCoord& b : bricks) {
    PLX_RETURN_IF_ERROR(SparseGrid::CheckBrickInsideWorld(b, voxel_size));
  }
  return CheckNoDuplicateBricks(bricks);
}

// ---------------------------------------------------------------------------------------------
// Writing.

// Buffers little-endian fields into large writes and checksums every byte it emits. The first
// error sticks and later calls do nothing, so the caller checks once, in Finish().
class MapWriter {
 public:
  explicit MapWriter(AtomicFileWriter* file) : file_(file) { buffer_.reserve(kIoChunkBytes); }

  void U32(uint32_t v) { Le(v, 4); }
  void I32(int32_t v) { Le(static_cast<uint32_t>(v), 4); }
  void U64(uint64_t v) { Le(v, 8); }
  void F32(float v) { Le(std::bit_cast<uint32_t>(v), 4); }

  void Bytes(const void* data, size_t size) {
    crc_.Update(data, size);
    Emit(static_cast<const uint8_t*>(data), size);
  }

  void Floats(const float* data, size_t count) {
    if constexpr (std::endian::native == std::endian::little) {
      Bytes(data, count * sizeof(float));
    } else {
      for (size_t i = 0; i < count; ++i) F32(data[i]);
    }
  }

  int64_t bytes_written() const { return bytes_written_; }

  // Appends the checksum of everything so far (not itself checksummed) and flushes.
  absl::Status Finish() {
    uint8_t trailer[kChecksumBytes];
    StoreLe(crc_.value(), 8, trailer);
    Emit(trailer, sizeof(trailer));
    Flush();
    return status_;
  }

 private:
  void Le(uint64_t v, int bytes) {
    uint8_t b[8];
    StoreLe(v, bytes, b);
    Bytes(b, static_cast<size_t>(bytes));
  }

  void Emit(const uint8_t* data, size_t size) {
    bytes_written_ += static_cast<int64_t>(size);
    if (buffer_.size() + size <= kIoChunkBytes) {
      buffer_.insert(buffer_.end(), data, data + size);
      return;
    }
    Flush();
    WriteAll(data, size);  // large payloads go straight to the file
  }

  void Flush() {
    WriteAll(buffer_.data(), buffer_.size());
    buffer_.clear();
  }

  void WriteAll(const uint8_t* data, size_t size) {
    if (status_.ok()) {
      status_ = file_->Write(absl::string_view(reinterpret_cast<const char*>(data), size));
    }
  }

  AtomicFileWriter* file_;
  std::vector<uint8_t> buffer_;
  Crc64 crc_;
  int64_t bytes_written_ = 0;
  absl::Status status_;
};

// What the writer puts in the file besides the grid: the state of a version-2 file, its
// keyframe section already encoded (its size is a header field).
struct EncodedState {
  uint32_t version = kOldestMapFileVersion;
  uint64_t map_version = 0;
  uint32_t keyframes = 0;
  std::string section;
};

void WriteMap(const PlenoxelMap& map, const EncodedState& state, MapWriter& w) {
  const SparseGrid& grid = map.grid;
  const RenderOptions& r = map.render;
  const uint32_t source_bytes = static_cast<uint32_t>(map.source.size());
  w.Bytes(kMapFileMagic, sizeof(kMapFileMagic));
  w.U32(state.version);
  w.U32(static_cast<uint32_t>(HeaderBytes(state.version, source_bytes)));
  w.F32(grid.voxel_size());
  w.F32(r.step_voxels);
  w.F32(r.sigma_threshold);
  w.F32(r.stop_transmittance);
  w.F32(r.near);
  w.F32(r.far);
  for (int c = 0; c < 3; ++c) w.F32(r.background[c]);
  for (int a = 0; a < 3; ++a) w.I32(grid.index_min()[a]);
  for (int a = 0; a < 3; ++a) w.I32(grid.index_dims()[a]);
  w.U32(source_bytes);
  w.Bytes(map.source.data(), map.source.size());
  w.U64(static_cast<uint64_t>(grid.num_bricks()));
  if (state.version >= 2) {
    w.U64(state.map_version);
    w.U32(state.keyframes);
    w.U64(state.section.size());
  }
  for (const BrickCoord& b : grid.brick_coords()) {
    w.I32(b.x);
    w.I32(b.y);
    w.I32(b.z);
  }
  w.Bytes(state.section.data(), state.section.size());
  // Bricks are stored apart in memory (copy-on-write versions) but contiguously in the file:
  // every brick's densities, then every brick's SH.
  for (int64_t slot = 0; slot < grid.num_bricks(); ++slot) {
    w.Floats(grid.brick_density(slot), kDensityFloatsPerBrick);
  }
  for (int64_t slot = 0; slot < grid.num_bricks(); ++slot) {
    w.Floats(grid.brick_sh(slot), kShFloatsPerBrick);
  }
}

// The state as the file stores it: checked keyframe by keyframe (what the reader would refuse
// is never written) and encoded. The oldest version that holds it.
absl::StatusOr<EncodedState> EncodeState(const MapFileState& state) {
  EncodedState out;
  if (state.empty()) return out;
  out.version = kMapFileVersion;
  out.map_version = state.map_version;
  if (state.keyframes.size() > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(state.keyframes.size(), " keyframes"));
  }
  out.keyframes = static_cast<uint32_t>(state.keyframes.size());
  int64_t bytes = 0;
  for (size_t i = 0; i < state.keyframes.size(); ++i) {
    if (absl::Status s = CheckStorableKeyframe(state.keyframes[i]); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("keyframe ", i, ": ", s.message()));
    }
    bytes += EncodedMapKeyframeBytes(state.keyframes[i]);
  }
  out.section.reserve(static_cast<size_t>(bytes));
  for (const MapKeyframe& k : state.keyframes) AppendEncodedMapKeyframe(k, &out.section);
  return out;
}

absl::Status SaveMapUnguarded(const PlenoxelMap& map, const MapFileState& state,
                              const std::string& path) {
  const SparseGrid& grid = map.grid;
  const std::string what = absl::StrCat("cannot save map to ", path);
  // Refuse to write anything LoadMap would reject (the same checks), so a saved map always
  // loads again.
  if (absl::Status s = CheckStorableMap(grid.voxel_size(), map.source.size(), grid.index_min(),
                                        grid.index_dims(), grid.brick_coords());
      !s.ok()) {
    return absl::Status(s.code(), absl::StrCat(what, ": ", s.message()));
  }
  absl::StatusOr<EncodedState> encoded = EncodeState(state);
  if (!encoded.ok()) {
    return absl::Status(encoded.status().code(),
                        absl::StrCat(what, ": ", encoded.status().message()));
  }
  const int64_t bricks = grid.num_bricks();

  // Not "<name>.plx.tmp.<pid>.plx": a leftover temporary must not look like a map to the
  // daemon, which loads every *.plx of its data dir.
  PLX_ASSIGN_OR_RETURN(AtomicFileWriter file,
                       AtomicFileWriter::Open(path, what, /*keep_extension=*/false));
  MapWriter writer(&file);
  WriteMap(map, *encoded, writer);
  PLX_RETURN_IF_ERROR(writer.Finish());
  const int64_t expected = HeaderBytes(encoded->version, map.source.size()) +
                           bricks * kBytesPerBrick +
                           static_cast<int64_t>(encoded->section.size()) + kChecksumBytes;
  if (writer.bytes_written() != expected) {
    return absl::InternalError(absl::StrCat(what, ": wrote ", writer.bytes_written(),
                                            " bytes, the layout needs ", expected));
  }
  PLX_RETURN_IF_ERROR(file.Finish());
  return file.Commit();
}

absl::StatusOr<LoadedMapFile> LoadMapUnguarded(const std::string& path,
                                               const LoadMapOptions& options) {
  PLX_ASSIGN_OR_RETURN(const OpenedFile file, OpenForRead(path));
  PLX_ASSIGN_OR_RETURN(ParsedHeader header, ReadHeader(file, path));
  if (options.max_memory_bytes > 0) {
    // From the header alone, before the payload is read or anything allocated.
    const int64_t needed =
        SparseGrid::EstimateMemory(header.info.bricks, header.info.index_dims).total_bytes();
    if (needed > options.max_memory_bytes) {
      return absl::ResourceExhaustedError(absl::StrCat(
          path, ": the map needs at least ", needed / 1000000, " MB (", header.info.bricks,
          " bricks), over the limit of ", options.max_memory_bytes / 1000000, " MB per map"));
    }
  }
  PLX_RETURN_IF_ERROR(VerifyChecksum(file, path));
  const MapFileInfo& info = header.info;
  const int64_t n = info.bricks;

  // Sizes below are bounded by the file's real size, checked in ReadHeader.
  std::vector<uint8_t> table(static_cast<size_t>(n * kTableBytesPerBrick));
  PLX_RETURN_IF_ERROR(
      ReadExactAt(file.fd.get(), header.header_bytes, table.data(), table.size(), path));
  std::vector<BrickCoord> bricks(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    const uint8_t* p = table.data() + i * kTableBytesPerBrick;
    bricks[i] = {LoadI32(p), LoadI32(p + 4), LoadI32(p + 8)};
  }
  table = {};
  // The same checks SaveMap makes before writing (a file that fails them was not written by it).
  if (absl::Status s = CheckStorableMap(info.voxel_size, info.source.size(), info.index_min,
                                        info.index_dims, bricks);
      !s.ok()) {
    return absl::DataLossError(absl::StrCat(path, ": ", s.message(), "; the file is corrupt"));
  }
  LoadedMapFile out;
  out.state.map_version = info.map_version;
  if (info.keyframe_bytes > 0 || info.keyframes > 0) {
    // Before the grid: a bad keyframe fails the load without gigabytes read for nothing.
    std::string section(static_cast<size_t>(info.keyframe_bytes), '\0');
    PLX_RETURN_IF_ERROR(ReadExactAt(file.fd.get(), header.keyframes_offset(), section.data(),
                                    section.size(), path));
    absl::StatusOr<MapKeyframes> keyframes = DecodeMapKeyframes(section, info.keyframes);
    if (!keyframes.ok()) {
      return absl::DataLossError(
          absl::StrCat(path, ": ", keyframes.status().message(), "; the file is corrupt"));
    }
    out.state.keyframes = *std::move(keyframes);
  }

  auto map = std::make_unique<PlenoxelMap>(info.voxel_size);
  map->render = info.render;
  map->source = info.source;
  // The saved index bounds first (bit-identical renders), then one call in table order gives
  // every brick its saved slot, so the payload copies verbatim.
  if (absl::Status s = map->grid.SetIndexBounds(info.index_min, info.index_dims); !s.ok()) {
    return absl::DataLossError(absl::StrCat(path, ": bad index bounds: ", s.message()));
  }
  const absl::StatusOr<int64_t> added = map->grid.AllocateBricks(bricks);
  if (!added.ok()) {
    return absl::Status(added.status().code(),
                        absl::StrCat(path, ": ", added.status().message()));
  }
  if (*added != n || map->grid.num_bricks() != n) {
    return absl::InternalError(absl::StrCat(path, ": rebuilt grid has ", map->grid.num_bricks(),
                                            " bricks, the file has ", n));
  }
  int64_t offset = header.payload_offset();
  for (int64_t slot = 0; slot < n; ++slot) {
    PLX_RETURN_IF_ERROR(ReadFloatsAt(file.fd.get(), offset, map->grid.mutable_brick_density(slot),
                                     kDensityFloatsPerBrick, path));
    offset += kDensityFloatsPerBrick * static_cast<int64_t>(sizeof(float));
  }
  for (int64_t slot = 0; slot < n; ++slot) {
    PLX_RETURN_IF_ERROR(ReadFloatsAt(file.fd.get(), offset, map->grid.mutable_brick_sh(slot),
                                     kShFloatsPerBrick, path));
    offset += kShFloatsPerBrick * static_cast<int64_t>(sizeof(float));
  }
  out.map = std::move(map);
  return out;
}

}  // namespace

absl::Status SaveMap(const PlenoxelMap& map, const std::string& path) {
  return SaveMap(map, MapFileState(), path);
}

absl::Status SaveMap(const PlenoxelMap& map, const MapFileState& state, const std::string& path) {
  return CatchAllocationFailure(absl::StrCat("saving ", path),
                                [&] { return SaveMapUnguarded(map, state, path); });
}

absl::StatusOr<MapFileInfo> ReadMapInfo(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const OpenedFile file, OpenForRead(path));
  PLX_ASSIGN_OR_RETURN(ParsedHeader header, ReadHeader(file, path));
  return std::move(header.info);
}

absl::StatusOr<LoadedMapFile> LoadMapFile(const std::string& path,
                                          const LoadMapOptions& options) {
  // A request's allocation failure (the brick table, the grid) fails the request, not the
  // process.
  return CatchAllocationFailure(absl::StrCat("loading ", path), [&] {
    return LoadMapUnguarded(path, options);
  });
}

absl::StatusOr<std::unique_ptr<PlenoxelMap>> LoadMap(const std::string& path,
                                                     const LoadMapOptions& options) {
  PLX_ASSIGN_OR_RETURN(LoadedMapFile loaded, LoadMapFile(path, options));
  return std::move(loaded.map);
}

}  // namespace plx

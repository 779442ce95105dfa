// Map files (core/formats/map_file.h): bit-exact round trips, every kind of damaged or foreign file
// rejected with a clear error, and saves that never leave a half-written map behind.
#include "core/formats/map_file.h"

#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_cat.h"
#include "core/cpu/cpu_backend.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/io/checksum.h"
#include "core/kernels/backend.h"
#include "core/render/render_view.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/fifo_valve.h"
#include "tests/grid_fill.h"
#include "tests/test_util.h"

namespace plx {
namespace map_file_test {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

// Offsets of the version-1 layout (map_file.h) that the damage tests poke at.
constexpr size_t kVersionOffset = 8;
constexpr size_t kVoxelSizeOffset = 16;
constexpr size_t kSourceOffset = 80;
constexpr size_t kBytesPerBrick = 12 + 512 * 28 * 4;

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

void StoreLe(std::string& bytes, size_t offset, uint64_t value, int width) {
  for (int i = 0; i < width; ++i) bytes[offset + i] = static_cast<char>(value >> (8 * i));
}

// Recomputes the trailing checksum after a deliberate edit, so the test reaches the check it is
// aimed at instead of stopping at "checksum mismatch".
void Reseal(std::string& bytes) {
  const size_t covered = bytes.size() - 8;
  StoreLe(bytes, covered, Crc64Of(bytes.data(), covered), 8);
}

std::string Msg(const absl::Status& status) { return std::string(status.message()); }

std::vector<std::string> ListDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

// Uniform in [lo, hi) from raw mt19937 output, whose sequence the standard fixes (unlike the
// <random> distributions), so the values are the same with every standard library.
float Uniform(std::mt19937& rng, float lo, float hi) {
  return lo + (hi - lo) * static_cast<float>(rng() >> 8) * (1.0f / 16777216.0f);
}

void FillRandom(PlenoxelMap& map, uint32_t seed, float density_lo, float density_hi) {
  std::mt19937 rng(seed);
  testing::FillDensity(map.grid, [&] { return Uniform(rng, density_lo, density_hi); });
  testing::FillSh(map.grid, [&] { return Uniform(rng, -0.5f, 0.5f); });
}

// A few bricks far apart and at negative coordinates, allocated in two calls so the slot order
// is not sorted, with non-default render options and binary-unsafe source text.
std::unique_ptr<PlenoxelMap> MakeTestMap() {
  auto map = std::make_unique<PlenoxelMap>(0.0173f);
  const std::vector<BrickCoord> first = {{-3, 7, 2}, {20, -11, 0}, {0, 0, 0}};
  const std::vector<BrickCoord> second = {{5, 5, -9}, {-1, -1, -1}};
  EXPECT_TRUE(map->grid.AllocateBricks(first).ok());
  EXPECT_TRUE(map->grid.AllocateBricks(second).ok());
  FillRandom(*map, 1234u, -2.0f, 40.0f);
  // Values that arithmetic would disturb: the file layer must copy bits, never compute on them.
  map->grid.mutable_brick_density(0)[0] = -0.0f;
  map->grid.mutable_brick_density(0)[1] = std::numeric_limits<float>::denorm_min();
  map->grid.mutable_brick_sh(0)[2] = std::bit_cast<float>(0x7fc01234u);  // NaN with a payload
  map->render.step_voxels = 0.37f;
  map->render.sigma_threshold = 0.02f;
  map->render.stop_transmittance = 3e-3f;
  map->render.near = 0.11f;
  map->render.far = 7.5f;
  map->render.background[0] = 0.1f;
  map->render.background[1] = 0.7f;
  map->render.background[2] = 0.9f;
  static constexpr char kSource[] = "tum_fr3_teddy frames 0-120\r\n\0\xff tail";
  map->source.assign(kSource, sizeof(kSource) - 1);
  return map;
}

void ExpectBitsEqual(float a, float b) {
  EXPECT_EQ(std::bit_cast<uint32_t>(a), std::bit_cast<uint32_t>(b));
}

void ExpectSameMap(const PlenoxelMap& expected, const PlenoxelMap& actual) {
  ExpectBitsEqual(expected.grid.voxel_size(), actual.grid.voxel_size());
  ExpectBitsEqual(expected.render.step_voxels, actual.render.step_voxels);
  ExpectBitsEqual(expected.render.sigma_threshold, actual.render.sigma_threshold);
  ExpectBitsEqual(expected.render.stop_transmittance, actual.render.stop_transmittance);
  ExpectBitsEqual(expected.render.near, actual.render.near);
  ExpectBitsEqual(expected.render.far, actual.render.far);
  for (int c = 0; c < 3; ++c) {
    ExpectBitsEqual(expected.render.background[c], actual.render.background[c]);
  }
  EXPECT_EQ(expected.source, actual.source);
  ASSERT_EQ(expected.grid.brick_coords(), actual.grid.brick_coords());
  for (const BrickCoord& b : expected.grid.brick_coords()) {
    EXPECT_EQ(expected.grid.FindBrick(b), actual.grid.FindBrick(b));
  }
  const std::vector<float> expected_density = expected.grid.DensityValues();
  const std::vector<float> actual_density = actual.grid.DensityValues();
  const std::vector<float> expected_sh = expected.grid.ShValues();
  const std::vector<float> actual_sh = actual.grid.ShValues();
  ASSERT_EQ(expected_density.size(), actual_density.size());
  ASSERT_EQ(expected_sh.size(), actual_sh.size());
  // Bit patterns, not float ==: a NaN must round-trip as itself. (memcmp on an empty vector's
  // null data() is undefined, which UBSan reports: compare element by element.)
  const auto same_bits = [](float a, float b) {
    return std::memcmp(&a, &b, sizeof(float)) == 0;
  };
  EXPECT_TRUE(std::equal(expected_density.begin(), expected_density.end(),
                         actual_density.begin(), same_bits));
  EXPECT_TRUE(std::equal(expected_sh.begin(), expected_sh.end(), actual_sh.begin(), same_bits));
}

class MapFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = plx::testing::MakeTempDir("map_file_test");
    path_ = dir_ + "/room.plxmap";
  }
  void TearDown() override {
    std::error_code ec;
    fs::permissions(dir_, fs::perms::owner_all, fs::perm_options::add, ec);
    fs::remove_all(dir_, ec);
  }

  // Saves the test map and returns the file's bytes.
  std::string SaveTestMap() {
    const auto map = MakeTestMap();
    EXPECT_TRUE(SaveMap(*map, path_).ok());
    return ReadBytes(path_);
  }

  absl::Status LoadBytes(const std::string& bytes) {
    WriteBytes(path_, bytes);
    return LoadMap(path_).status();
  }

  std::string dir_;
  std::string path_;
};

TEST_F(MapFileTest, RoundTripIsBitExact) {
  const auto map = MakeTestMap();
  ASSERT_TRUE(SaveMap(*map, path_).ok());
  const absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameMap(*map, **loaded);
  // Saving the loaded map again reproduces the file byte for byte, index bounds included.
  const std::string first = ReadBytes(path_);
  ASSERT_TRUE(SaveMap(**loaded, path_).ok());
  EXPECT_EQ(first, ReadBytes(path_));
}

TEST_F(MapFileTest, EmptyMapRoundTrips) {
  PlenoxelMap map(0.02f);
  ASSERT_TRUE(SaveMap(map, path_).ok());
  EXPECT_EQ(fs::file_size(path_), 96u);  // header with no source + checksum
  const absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameMap(map, **loaded);
  EXPECT_EQ((*loaded)->grid.num_bricks(), 0);
}

// The payload and index bounds come back identical, so the same camera renders the same bits,
// even for a grid whose index grew over several allocations.
TEST_F(MapFileTest, LoadedMapRendersBitIdentically) {
  PlenoxelMap map(0.05f);
  std::vector<BrickCoord> bricks;
  for (int z = 5; z <= 6; ++z)
    for (int y = -1; y <= 0; ++y)
      for (int x = -1; x <= 0; ++x) bricks.push_back({x, y, z});
  std::shuffle(bricks.begin(), bricks.end(), std::mt19937(7));
  ASSERT_TRUE(map.grid.AllocateBricks(absl::MakeSpan(bricks).subspan(0, 3)).ok());
  ASSERT_TRUE(map.grid.AllocateBricks(absl::MakeSpan(bricks).subspan(3)).ok());
  FillRandom(map, 99u, 0.0f, 30.0f);
  ASSERT_TRUE(SaveMap(map, path_).ok());
  absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_EQ(map.grid.index_min(), (*loaded)->grid.index_min());
  ASSERT_EQ(map.grid.index_dims(), (*loaded)->grid.index_dims());

  PinholeIntrinsics k;
  k.fx = k.fy = 40.0;
  k.cx = 15.5;
  k.cy = 11.5;
  k.width = 32;
  k.height = 24;
  const std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const RenderedPixels a = RenderPixels(*backend, map, SE3::Identity(), k).value();
  const RenderedPixels b = RenderPixels(*backend, **loaded, SE3::Identity(), k).value();
  ASSERT_GT(*std::max_element(a.opacity.begin(), a.opacity.end()), 0.5f) << "map not in view";
  EXPECT_EQ(0, std::memcmp(a.color.data(), b.color.data(), a.color.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(a.depth.data(), b.depth.data(), a.depth.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(a.opacity.data(), b.opacity.data(), a.opacity.size() * sizeof(float)));
}

TEST_F(MapFileTest, ReadMapInfoReportsHeader) {
  const auto map = MakeTestMap();
  ASSERT_TRUE(SaveMap(*map, path_).ok());
  const absl::StatusOr<MapFileInfo> info = ReadMapInfo(path_);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version, 1u);  // nothing but the grid: the oldest version that holds it
  ExpectBitsEqual(info->voxel_size, 0.0173f);
  EXPECT_EQ(info->bricks, 5);
  EXPECT_EQ(info->bytes, static_cast<int64_t>(fs::file_size(path_)));
  EXPECT_EQ(info->bytes, static_cast<int64_t>(88 + map->source.size() + 5 * kBytesPerBrick + 8));
  EXPECT_EQ(info->source, map->source);
  ExpectBitsEqual(info->render.far, 7.5f);
  EXPECT_EQ(info->index_min, map->grid.index_min());
  EXPECT_EQ(info->index_dims, map->grid.index_dims());
}

TEST_F(MapFileTest, TruncatedFileIsRejected) {
  const std::string bytes = SaveTestMap();
  const size_t table = 88 + MakeTestMap()->source.size();
  // Inside the magic, inside the fixed header, inside the source text, inside the brick table,
  // inside the payload, just before the checksum, inside the checksum.
  for (size_t cut : {size_t{5}, size_t{10}, size_t{40}, size_t{85}, table + 7, table + 1000,
                     bytes.size() / 2, bytes.size() - 8, bytes.size() - 1}) {
    SCOPED_TRACE(cut);
    const absl::Status status = LoadBytes(bytes.substr(0, cut));
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(Msg(status), HasSubstr("truncated"));
    EXPECT_THAT(Msg(status), HasSubstr(path_));
    EXPECT_THAT(Msg(status), HasSubstr(absl::StrCat("found ", cut)));
    EXPECT_FALSE(ReadMapInfo(path_).ok());
  }
  // Past the header the message gives the exact size the brick count needs.
  const absl::Status status = LoadBytes(bytes.substr(0, bytes.size() - 1));
  EXPECT_THAT(Msg(status),
              HasSubstr(absl::StrCat("expected ", bytes.size(), " bytes for 5 bricks")));
}

TEST_F(MapFileTest, FlippedPayloadByteFailsChecksum) {
  const std::string bytes = SaveTestMap();
  const size_t table = 88 + MakeTestMap()->source.size();
  // Brick table, first density byte, the last payload byte, the checksum itself, and a spread
  // of positions in between.
  std::vector<size_t> offsets = {table, table + 5 * 12, bytes.size() - 9, bytes.size() - 1};
  for (size_t i = table; i < bytes.size(); i += 9973) offsets.push_back(i);
  for (size_t offset : offsets) {
    SCOPED_TRACE(offset);
    std::string damaged = bytes;
    damaged[offset] = static_cast<char>(damaged[offset] ^ 0x10);
    const absl::Status status = LoadBytes(damaged);
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(Msg(status), HasSubstr(path_ + ": checksum mismatch, the file is corrupt"));
  }
}

TEST_F(MapFileTest, AnyHeaderByteFlipIsRejected) {
  const std::string bytes = SaveTestMap();
  const size_t table = 88 + MakeTestMap()->source.size();
  for (size_t offset = 0; offset < table; ++offset) {
    SCOPED_TRACE(offset);
    std::string damaged = bytes;
    damaged[offset] = static_cast<char>(damaged[offset] ^ 0x01);
    EXPECT_FALSE(LoadBytes(damaged).ok());
  }
}

TEST_F(MapFileTest, ForeignFileIsNotAMap) {
  std::vector<uchar> png;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(4, 4, CV_8UC3, cv::Scalar(1, 2, 3)), png));
  const std::string text = "# fx fy cx cy width height depth_scale\n535.4 539.2 320.1 247.6\n";
  // The last is a short file whose first bytes are almost the magic.
  const std::string short_file = "PLXMAP\n";
  for (const std::string& bytes : {std::string(png.begin(), png.end()), text, short_file}) {
    const absl::Status status = LoadBytes(bytes);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
    EXPECT_EQ(Msg(status), path_ + ": not a plenoxd map file");
    EXPECT_EQ(ReadMapInfo(path_).status(), status);
  }
  // A map copied in text mode (CRLF -> LF) fails at the magic already.
  std::string mangled = SaveTestMap();
  mangled.erase(6, 1);
  EXPECT_EQ(LoadBytes(mangled).code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(MapFileTest, OtherVersionIsRejected) {
  for (uint32_t version : {0u, 3u, 0x01000000u}) {
    std::string bytes = SaveTestMap();
    StoreLe(bytes, kVersionOffset, version, 4);
    Reseal(bytes);
    const absl::Status status = LoadBytes(bytes);
    EXPECT_EQ(status.code(), absl::StatusCode::kUnimplemented) << status;
    EXPECT_THAT(Msg(status), HasSubstr(absl::StrCat("version ", version, " is not supported")));
    EXPECT_THAT(Msg(status), HasSubstr("this build reads versions 1 to 2"));
  }
}

TEST_F(MapFileTest, BadVoxelSizeIsRejected) {
  for (float voxel : {0.0f, -0.01f, std::numeric_limits<float>::infinity(),
                      std::numeric_limits<float>::quiet_NaN()}) {
    SCOPED_TRACE(voxel);
    std::string bytes = SaveTestMap();
    StoreLe(bytes, kVoxelSizeOffset, std::bit_cast<uint32_t>(voxel), 4);
    Reseal(bytes);
    const absl::Status status = LoadBytes(bytes);
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(Msg(status), HasSubstr("is not a positive finite number"));
  }
  // The saver refuses to write what the loader would reject.
  EXPECT_EQ(SaveMap(PlenoxelMap(0.0f), dir_ + "/zero.plxmap").code(),
            absl::StatusCode::kInvalidArgument);
}

// A corrupt count must be caught from the file size, before anything is allocated from it.
TEST_F(MapFileTest, BrickCountInconsistentWithSizeIsRejected) {
  const std::string bytes = SaveTestMap();
  const size_t count_offset = kSourceOffset + MakeTestMap()->source.size();
  const struct {
    uint64_t count;
    const char* message;
  } cases[] = {
      {uint64_t{1} << 62, "exceeds the limit"},
      {uint64_t{1} << 40, "exceeds the limit"},
      {6, "truncated"},
      {4, "brick count 4 is inconsistent with the file size"},
      {0, "brick count 0 is inconsistent with the file size"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.count);
    std::string damaged = bytes;
    StoreLe(damaged, count_offset, c.count, 8);
    Reseal(damaged);
    const absl::Status status = LoadBytes(damaged);
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(Msg(status), HasSubstr(c.message));
  }
}

TEST_F(MapFileTest, OversizedSourceLengthIsRejected) {
  std::string bytes = SaveTestMap();
  StoreLe(bytes, kSourceOffset - 4, 0xfffffff0u, 4);
  Reseal(bytes);
  const absl::Status status = LoadBytes(bytes);
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
  EXPECT_THAT(Msg(status), HasSubstr("source text length 4294967280 exceeds the limit"));

  PlenoxelMap map(0.02f);
  map.source.assign(kMaxMapSourceBytes + 1, 'x');
  EXPECT_EQ(SaveMap(map, path_).code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(MapFileTest, DuplicateBrickIsRejected) {
  std::string bytes = SaveTestMap();
  const size_t table = 88 + MakeTestMap()->source.size();
  bytes.replace(table + 3 * 12, 12, bytes.substr(table + 1 * 12, 12));  // entry 3 := entry 1
  Reseal(bytes);
  const absl::Status status = LoadBytes(bytes);
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
  EXPECT_THAT(Msg(status),
              HasSubstr("brick (20, -11, 0) appears twice in the brick table (entries 1 and 3)"));
}

// What SaveMap writes, LoadMap reads: maps whose bricks sit at the very edges of the world
// extent (core/common/world_extent.h), at the finest, the default and the coarsest voxel
// sizes, come back bit-exact.
TEST_F(MapFileTest, MapsAtTheWorldsEdgesRoundTrip) {
  for (float voxel : {0.001f, 0.02f, 1.0f}) {
    const BrickRange r = SparseGrid::WorldBrickRange(voxel);
    const int32_t lo = static_cast<int32_t>(r.lo), hi = static_cast<int32_t>(r.hi);
    const std::vector<std::vector<BrickCoord>> corners = {
        {{hi, hi, hi}, {hi - 1, hi, hi - 2}},
        {{lo, lo, lo}, {lo + 2, lo, lo + 1}},
        {{lo, hi, 0}, {lo + 1, hi - 1, -1}}};
    for (const std::vector<BrickCoord>& bricks : corners) {
      SCOPED_TRACE(absl::StrCat("voxel ", voxel, " brick ", bricks[0].x, " ", bricks[0].y, " ",
                                bricks[0].z));
      PlenoxelMap map(voxel);
      ASSERT_TRUE(map.grid.AllocateBricks(bricks).ok());
      FillRandom(map, 99u, -1.0f, 10.0f);
      ASSERT_TRUE(SaveMap(map, path_).ok());
      const absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_);
      ASSERT_TRUE(loaded.ok()) << loaded.status();
      ExpectSameMap(map, **loaded);
      EXPECT_EQ((*loaded)->grid.index_min(), map.grid.index_min());
      EXPECT_EQ((*loaded)->grid.index_dims(), map.grid.index_dims());
    }
  }
}

// A brick table entry outside the world (what a far keyframe used to allocate) is corruption:
// SaveMap can no longer write one, so LoadMap says so instead of allocating around it.
TEST_F(MapFileTest, BrickOutsideTheWorldIsRejected) {
  std::string bytes = SaveTestMap();
  const size_t table = 88 + MakeTestMap()->source.size();
  StoreLe(bytes, table + 2 * 12, static_cast<uint32_t>(int32_t{1} << 30), 4);  // entry 2's x
  Reseal(bytes);
  const absl::Status status = LoadBytes(bytes);
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
  EXPECT_THAT(Msg(status), HasSubstr("brick (1073741824, 0, 0) is outside the world extent"));
}

// A map over the caller's memory limit is refused from its header, before the payload is read
// or any brick allocated.
TEST_F(MapFileTest, MapOverTheMemoryLimitIsRefusedFromItsHeader) {
  const auto map = MakeTestMap();
  ASSERT_TRUE(SaveMap(*map, path_).ok());
  const int64_t needed = map->grid.Memory().total_bytes();
  LoadMapOptions tight;
  tight.max_memory_bytes = map->grid.Memory().parameter_bytes - 1;
  const absl::Status refused = LoadMap(path_, tight).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_THAT(Msg(refused), HasSubstr("over the limit of"));
  // Even a corrupt payload is not read: the limit comes first.
  std::string bytes = ReadBytes(path_);
  bytes[bytes.size() - 100] ^= 1;
  WriteBytes(path_, bytes);
  EXPECT_EQ(LoadMap(path_, tight).status().code(), absl::StatusCode::kResourceExhausted);
  ASSERT_TRUE(SaveMap(*map, path_).ok());
  LoadMapOptions enough;
  enough.max_memory_bytes = needed;
  const absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_, enough);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameMap(*map, **loaded);
}

TEST_F(MapFileTest, MissingFileIsNotFound) {
  const absl::Status status = LoadMap(dir_ + "/nope.plxmap").status();
  EXPECT_EQ(status.code(), absl::StatusCode::kNotFound) << status;
  EXPECT_THAT(Msg(status), HasSubstr(dir_ + "/nope.plxmap"));
  EXPECT_EQ(ReadMapInfo(dir_ + "/nope.plxmap").status().code(), absl::StatusCode::kNotFound);
  // A directory is not a map either (and must not read as an empty, "truncated" one).
  EXPECT_EQ(LoadMap(dir_).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(MapFileTest, SaveIntoMissingDirectoryFailsCleanly) {
  const std::string missing = dir_ + "/no/such";
  const absl::Status status = SaveMap(*MakeTestMap(), missing + "/room.plxmap");
  EXPECT_EQ(status.code(), absl::StatusCode::kNotFound) << status;
  EXPECT_THAT(Msg(status), HasSubstr("directory " + missing + " does not exist"));
  EXPECT_THAT(ListDir(dir_), ::testing::IsEmpty());
}

TEST_F(MapFileTest, SaveReplacesExistingMap) {
  PlenoxelMap old_map(0.02f);
  old_map.source = "old";
  ASSERT_TRUE(SaveMap(old_map, path_).ok());
  const auto new_map = MakeTestMap();
  ASSERT_TRUE(SaveMap(*new_map, path_).ok());
  const absl::StatusOr<std::unique_ptr<PlenoxelMap>> loaded = LoadMap(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameMap(*new_map, **loaded);
  EXPECT_THAT(ListDir(dir_), ElementsAre("room.plxmap"));  // no temp file left
}

// A write that fails halfway (here: the file-size limit, which binds root too) must leave the
// previous map intact and remove the partial temp file.
TEST_F(MapFileTest, FailedWriteKeepsOldFileAndRemovesTemp) {
  PlenoxelMap old_map(0.02f);
  old_map.source = "old";
  ASSERT_TRUE(SaveMap(old_map, path_).ok());
  const std::string old_bytes = ReadBytes(path_);

  const auto big = MakeTestMap();  // ~290 KB, well over the limit below
  struct rlimit saved;
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  if (saved.rlim_cur != RLIM_INFINITY && saved.rlim_cur < 64 * 1024) {
    GTEST_SKIP() << "file size limit already below 64 KiB";
  }
  struct rlimit small = saved;
  small.rlim_cur = 64 * 1024;
  // Exceeding the limit raises SIGXFSZ, which would kill the test; ignored, write fails EFBIG.
  const auto previous_handler = signal(SIGXFSZ, SIG_IGN);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const absl::Status status = SaveMap(*big, path_);
  setrlimit(RLIMIT_FSIZE, &saved);
  signal(SIGXFSZ, previous_handler);

  EXPECT_FALSE(status.ok());
  EXPECT_THAT(Msg(status), HasSubstr(path_));
  EXPECT_THAT(Msg(status), HasSubstr("File too large"));
  EXPECT_EQ(ReadBytes(path_), old_bytes);
  EXPECT_THAT(ListDir(dir_), ElementsAre("room.plxmap"));
}

TEST_F(MapFileTest, SaveIntoReadOnlyDirectoryKeepsOldFile) {
  if (geteuid() == 0) {
    // Root ignores directory permissions, so this failure cannot be provoked; the failed-write
    // and failed-rename tests cover the same cleanup paths.
    GTEST_SKIP() << "running as root";
  }
  PlenoxelMap old_map(0.02f);
  ASSERT_TRUE(SaveMap(old_map, path_).ok());
  const std::string old_bytes = ReadBytes(path_);
  fs::permissions(dir_, fs::perms::owner_write | fs::perms::group_write | fs::perms::others_write,
                  fs::perm_options::remove);
  const absl::Status status = SaveMap(*MakeTestMap(), path_);
  fs::permissions(dir_, fs::perms::owner_write, fs::perm_options::add);
  EXPECT_EQ(status.code(), absl::StatusCode::kPermissionDenied) << status;
  EXPECT_THAT(Msg(status), HasSubstr(path_));
  EXPECT_EQ(ReadBytes(path_), old_bytes);
  EXPECT_THAT(ListDir(dir_), ElementsAre("room.plxmap"));
}

// The rename is the last step; when it fails (target is a non-empty directory) the complete
// temp file must still be removed.
TEST_F(MapFileTest, FailedRenameRemovesTemp) {
  fs::create_directories(path_ + "/occupied");
  const absl::Status status = SaveMap(*MakeTestMap(), path_);
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(Msg(status), HasSubstr("renaming"));
  EXPECT_THAT(ListDir(dir_), ElementsAre("room.plxmap"));
  EXPECT_TRUE(fs::is_directory(path_ + "/occupied"));
}

// A FIFO named like a map (a daemon's data dir holds whatever is put there): reading it must
// fail at once, not wait in open() for a writer that never comes.
TEST_F(MapFileTest, FifoIsNotAMapAndNeverBlocks) {
  ASSERT_EQ(::mkfifo(path_.c_str(), 0644), 0) << std::strerror(errno);
  plx::testing::FifoValve valve(path_, plx::testing::FifoValve::Role::kWriter);
  const absl::Status loaded = LoadMap(path_).status();
  const absl::Status info = ReadMapInfo(path_).status();
  EXPECT_FALSE(valve.released()) << "LoadMap or ReadMapInfo blocked opening the FIFO";
  EXPECT_EQ(loaded.code(), absl::StatusCode::kInvalidArgument) << loaded;
  EXPECT_THAT(Msg(loaded), HasSubstr(path_ + ": not a regular file (a FIFO)"));
  EXPECT_EQ(info.code(), absl::StatusCode::kInvalidArgument) << info;
}

// The same for the writer: a FIFO at the temporary's name fails the save instead of blocking it.
TEST_F(MapFileTest, FifoAtTheTempNameFailsTheSaveWithoutBlocking) {
  const std::string temp = absl::StrCat(path_, ".tmp.", ::getpid());
  ASSERT_EQ(::mkfifo(temp.c_str(), 0644), 0) << std::strerror(errno);
  absl::Status saved;
  {
    plx::testing::FifoValve valve(temp, plx::testing::FifoValve::Role::kReader);
    saved = SaveMap(*MakeTestMap(), path_);
    EXPECT_FALSE(valve.released()) << "SaveMap blocked opening the FIFO";
  }
  EXPECT_FALSE(saved.ok());
  EXPECT_FALSE(fs::exists(path_));
}

// ---------------------------------------------------------------------------------------------
// The checksum itself.

// Bit-at-a-time CRC-64/XZ straight from the definition, to check the table-driven version.
uint64_t ReferenceCrc64(const uint8_t* data, size_t size) {
  uint64_t crc = ~uint64_t{0};
  for (size_t i = 0; i < size; ++i) {
    crc ^= data[i];
    for (int bit = 0; bit < 8; ++bit) {
      crc = (crc & 1) ? (crc >> 1) ^ 0xC96C5795D7870F42ull : crc >> 1;
    }
  }
  return ~crc;
}

TEST(MapFileChecksumTest, MatchesPublishedCheckValue) {
  EXPECT_EQ(Crc64Of("123456789", 9), 0x995DC9BBDF1939FAull);
  EXPECT_EQ(Crc64Of("", 0), 0u);
}

TEST(MapFileChecksumTest, MatchesReferenceAtEveryLengthAndAlignment) {
  std::mt19937 rng(5);
  std::vector<uint8_t> data(200);
  for (uint8_t& b : data) b = static_cast<uint8_t>(rng());
  for (size_t start = 0; start < 8; ++start) {
    for (size_t size = 0; start + size <= data.size(); size += 7) {
      ASSERT_EQ(Crc64Of(data.data() + start, size), ReferenceCrc64(data.data() + start, size))
          << "start " << start << " size " << size;
    }
  }
}

TEST(MapFileChecksumTest, PiecewiseUpdateEqualsOneShot) {
  std::mt19937 rng(6);
  std::vector<uint8_t> data(1000);
  for (uint8_t& b : data) b = static_cast<uint8_t>(rng());
  Crc64 crc;
  // Irregular piece sizes (1..61 bytes) so pieces straddle the 8-byte fast path every way.
  size_t piece = 1;
  for (size_t offset = 0; offset < data.size(); offset += piece, piece = piece * 3 % 61 + 1) {
    crc.Update(data.data() + offset, std::min(piece, data.size() - offset));
  }
  EXPECT_EQ(crc.value(), Crc64Of(data.data(), data.size()));
}

}  // namespace map_file_test
}  // namespace plx

// Map file format version 2 (core/formats/map_file.h, map_keyframes_codec.h): a map's keyframes
// and version number round-trip, their size is what the layout says, damage to them is
// DataLoss, the writer refuses what the reader would, and version-1 files (built here byte by
// byte from the documented layout, not by the writer) still load.
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/formats/map_file.h"
#include "core/formats/map_keyframes_codec.h"
#include "core/io/checksum.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/grid_fill.h"
#include "tests/test_util.h"

namespace plx {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr int64_t kBytesPerBrick = 12 + 512 * 28 * 4;

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

void AppendLe(std::string& bytes, uint64_t value, int width) {
  for (int i = 0; i < width; ++i) bytes.push_back(static_cast<char>(value >> (8 * i)));
}

void Reseal(std::string& bytes) {
  const size_t covered = bytes.size() - 8;
  StoreLe(bytes, covered, Crc64Of(bytes.data(), covered), 8);
}

std::unique_ptr<PlenoxelMap> SmallMap() {
  auto map = std::make_unique<PlenoxelMap>(0.02f);
  EXPECT_TRUE(map->grid.AllocateBricks({{0, 0, 0}, {-2, 3, 1}}).ok());
  float next = 0.0f;
  testing::FillDensity(map->grid, [&] { return next += 0.25f; });
  testing::FillSh(map->grid, [&] { return next -= 0.125f; });
  map->source = "keyframes test";
  return map;
}

// Features with `keypoints` keypoints and a `tw` x `th` thumbnail, from a fixed seed (raw
// mt19937 output, whose sequence the standard fixes).
std::shared_ptr<const FrameFeatures> Features(int keypoints, int tw, int th, uint32_t seed) {
  std::mt19937 rng(seed);
  const auto uniform = [&](float lo, float hi) {
    return lo + (hi - lo) * static_cast<float>(rng() >> 8) * (1.0f / 16777216.0f);
  };
  auto f = std::make_shared<FrameFeatures>();
  for (int i = 0; i < keypoints; ++i) {
    f->pixels.emplace_back(uniform(0, 640), uniform(0, 480));
    f->points.emplace_back(uniform(-2, 2), uniform(-2, 2), uniform(0.1f, 8));
    OrbDescriptor d;
    for (uint8_t& b : d) b = static_cast<uint8_t>(rng());
    f->descriptors.push_back(d);
  }
  f->thumbnail_width = tw;
  f->thumbnail_height = th;
  for (int i = 0; i < tw * th; ++i) f->thumbnail.push_back(uniform(-1, 1));
  return f;
}

MapKeyframe Keyframe(double t, double x, std::shared_ptr<const FrameFeatures> features) {
  MapKeyframe k;
  k.timestamp = t;
  k.pose = SE3(Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * x + 0.1, Eigen::Vector3d(1, 2, 3)
                                                                         .normalized())),
               Eigen::Vector3d(x, -0.5 * x, 1.25));
  k.intrinsics = {535.4, 539.2, 320.1, 247.6, 640, 480};
  k.features = std::move(features);
  return k;
}

// Three keyframes: full features, none at all (an Integrate stream's), no keypoints but a
// thumbnail (a textureless view).
MapFileState ThreeKeyframes() {
  MapFileState state;
  state.map_version = 42;
  state.keyframes.push_back(Keyframe(1.5, 0.0, Features(500, 40, 30, 7u)));
  state.keyframes.push_back(Keyframe(2.25, 0.5, nullptr));
  state.keyframes.push_back(Keyframe(3.0, 1.0, Features(0, 40, 30, 8u)));
  return state;
}

void ExpectSameKeyframes(const MapKeyframes& expected, const MapKeyframes& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    SCOPED_TRACE(i);
    const MapKeyframe& a = expected[i];
    const MapKeyframe& b = actual[i];
    EXPECT_EQ(a.timestamp, b.timestamp);
    EXPECT_EQ(a.pose.translation(), b.pose.translation());
    EXPECT_LT((a.pose.rotation().coeffs() - b.pose.rotation().coeffs()).norm(), 1e-15);
    EXPECT_EQ(a.intrinsics, b.intrinsics);
    ASSERT_EQ(a.features == nullptr, b.features == nullptr);
    if (a.features == nullptr) continue;
    EXPECT_EQ(a.features->pixels, b.features->pixels);
    EXPECT_EQ(a.features->points, b.features->points);
    EXPECT_EQ(a.features->descriptors, b.features->descriptors);
    EXPECT_EQ(a.features->thumbnail, b.features->thumbnail);
    EXPECT_EQ(a.features->thumbnail_width, b.features->thumbnail_width);
    EXPECT_EQ(a.features->thumbnail_height, b.features->thumbnail_height);
  }
}

class MapFileKeyframesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = plx::testing::MakeTempDir("map_file_keyframes_test");
    path_ = dir_ + "/room.plx";
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // The saved file of SmallMap with ThreeKeyframes.
  std::string SavedBytes() {
    EXPECT_TRUE(SaveMap(*SmallMap(), ThreeKeyframes(), path_).ok());
    return ReadBytes(path_);
  }
  absl::Status LoadBytes(const std::string& bytes) {
    WriteBytes(path_, bytes);
    return LoadMapFile(path_).status();
  }
  // Offsets in SavedBytes: the header, and the keyframe section after the brick table.
  static size_t HeaderBytes() { return 108 + std::string("keyframes test").size(); }
  static size_t SectionOffset() { return HeaderBytes() + 2 * 12; }

  std::string dir_, path_;
};

TEST_F(MapFileKeyframesTest, KeyframesAndVersionRoundTrip) {
  const std::unique_ptr<PlenoxelMap> map = SmallMap();
  const MapFileState state = ThreeKeyframes();
  ASSERT_TRUE(SaveMap(*map, state, path_).ok());
  const absl::StatusOr<MapFileInfo> info = ReadMapInfo(path_);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version, 2u);
  EXPECT_EQ(info->map_version, 42u);
  EXPECT_EQ(info->keyframes, 3);
  absl::StatusOr<LoadedMapFile> loaded = LoadMapFile(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->state.map_version, 42u);
  ExpectSameKeyframes(state.keyframes, loaded->state.keyframes);
  EXPECT_EQ(loaded->map->grid.DensityValues(), map->grid.DensityValues());
  EXPECT_EQ(loaded->map->grid.ShValues(), map->grid.ShValues());
  // LoadMap reads the same file (keyframes checked, not returned).
  EXPECT_TRUE(LoadMap(path_).ok());
  // And what was loaded saves again to the same bytes.
  const std::string first = ReadBytes(path_);
  ASSERT_TRUE(SaveMap(*loaded->map, loaded->state, path_).ok());
  EXPECT_TRUE(ReadBytes(path_) == first);
}

TEST_F(MapFileKeyframesTest, EachKeyframeCostsWhatTheLayoutSays) {
  const std::unique_ptr<PlenoxelMap> map = SmallMap();
  const MapFileState state = ThreeKeyframes();
  // 120 bytes, plus 52 per keypoint and 4 per thumbnail value.
  EXPECT_EQ(EncodedMapKeyframeBytes(state.keyframes[0]), 120 + 52 * 500 + 4 * 40 * 30);
  EXPECT_EQ(EncodedMapKeyframeBytes(state.keyframes[1]), 120);
  EXPECT_EQ(EncodedMapKeyframeBytes(state.keyframes[2]), 120 + 4 * 40 * 30);
  ASSERT_TRUE(SaveMap(*map, state, path_).ok());
  const int64_t section = (120 + 52 * 500 + 4 * 1200) + 120 + (120 + 4 * 1200);
  const int64_t expected =
      static_cast<int64_t>(HeaderBytes()) + 2 * kBytesPerBrick + section + 8;
  EXPECT_EQ(static_cast<int64_t>(fs::file_size(path_)), expected);
  const absl::StatusOr<MapFileInfo> info = ReadMapInfo(path_);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->keyframe_bytes, section);
  EXPECT_EQ(info->bytes, expected);
}

TEST_F(MapFileKeyframesTest, WithoutStateTheWriterKeepsVersionOne) {
  // A map without keyframes or a version number opens in builds that read only version 1.
  ASSERT_TRUE(SaveMap(*SmallMap(), MapFileState(), path_).ok());
  const absl::StatusOr<MapFileInfo> info = ReadMapInfo(path_);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version, 1u);
  EXPECT_EQ(info->bytes, static_cast<int64_t>(88 + 14 + 2 * kBytesPerBrick + 8));
  // A version number alone is state: version 2 with no keyframes.
  MapFileState numbered;
  numbered.map_version = 7;
  ASSERT_TRUE(SaveMap(*SmallMap(), numbered, path_).ok());
  absl::StatusOr<LoadedMapFile> loaded = LoadMapFile(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->state.map_version, 7u);
  EXPECT_TRUE(loaded->state.keyframes.empty());
  EXPECT_EQ(ReadMapInfo(path_)->version, 2u);
}

// A version-1 file as an older build wrote it, assembled from the layout in map_file.h (not by
// SaveMap): one brick at (1, -2, 3) whose vertex v has density v / 4 and SH coefficient
// c of vertex v = c - v.
TEST_F(MapFileKeyframesTest, AVersionOneFileFromTheDocumentedLayoutLoads) {
  const std::string source = "old";
  std::string bytes = "PLXMAP\r\n";
  AppendLe(bytes, 1, 4);                        // version
  AppendLe(bytes, 88 + source.size(), 4);       // header size
  AppendLe(bytes, std::bit_cast<uint32_t>(0.05f), 4);  // voxel size
  for (float r : {0.5f, 0.01f, 1e-4f, 0.0f, 20.0f, 0.0f, 0.0f, 0.0f}) {  // render options
    AppendLe(bytes, std::bit_cast<uint32_t>(r), 4);
  }
  for (int32_t v : {1, -2, 3, 1, 1, 1}) AppendLe(bytes, static_cast<uint32_t>(v), 4);  // index
  AppendLe(bytes, source.size(), 4);
  bytes += source;
  AppendLe(bytes, 1, 8);  // one brick
  for (int32_t c : {1, -2, 3}) AppendLe(bytes, static_cast<uint32_t>(c), 4);
  for (int v = 0; v < 512; ++v) AppendLe(bytes, std::bit_cast<uint32_t>(v / 4.0f), 4);
  for (int v = 0; v < 512; ++v) {
    for (int c = 0; c < 27; ++c) {
      AppendLe(bytes, std::bit_cast<uint32_t>(static_cast<float>(c - v)), 4);
    }
  }
  AppendLe(bytes, Crc64Of(bytes.data(), bytes.size()), 8);
  WriteBytes(path_, bytes);

  absl::StatusOr<LoadedMapFile> loaded = LoadMapFile(path_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->state.map_version, 0u);
  EXPECT_TRUE(loaded->state.keyframes.empty());
  const PlenoxelMap& map = *loaded->map;
  EXPECT_EQ(map.grid.voxel_size(), 0.05f);
  EXPECT_EQ(map.source, "old");
  ASSERT_EQ(map.grid.num_bricks(), 1);
  EXPECT_EQ(map.grid.brick_coords()[0], (BrickCoord{1, -2, 3}));
  EXPECT_EQ(map.grid.brick_density(0)[511], 511 / 4.0f);
  EXPECT_EQ(map.grid.brick_sh(0)[27 * 10 + 5], static_cast<float>(5 - 10));
  const absl::StatusOr<MapFileInfo> info = ReadMapInfo(path_);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version, 1u);
  EXPECT_EQ(info->keyframes, 0);
}

TEST_F(MapFileKeyframesTest, DamagedKeyframesAreDataLoss) {
  const std::string saved = SavedBytes();
  const size_t section = SectionOffset();
  const size_t second = section + 120 + 52 * 500 + 4 * 1200;  // the keyframe without features
  const struct {
    const char* what;
    size_t offset;
    uint64_t value;
    int width;
    const char* message;
  } cases[] = {
      {"timestamp", section, std::bit_cast<uint64_t>(std::nan("")), 8,
       "keyframe 0: timestamp nan is not finite"},
      {"rotation", section + 32, std::bit_cast<uint64_t>(0.9), 8,
       "keyframe 0: the rotation is not a unit quaternion"},
      {"position", section + 8, std::bit_cast<uint64_t>(1e7), 8, "keyframe 0: pose"},
      {"focal length", section + 64, std::bit_cast<uint64_t>(-1.0), 8,
       "keyframe 0: intrinsics"},
      {"width", section + 96, 0, 4, "keyframe 0: intrinsics"},
      {"flags", section + 104, 6, 4, "keyframe 0: unknown flags 6"},
      {"keypoints", section + 108, 0xffffffffu, 4, "keyframe 0: 4294967295 keypoints"},
      {"thumbnail", section + 116, 0, 4, "keyframe 0: features: thumbnail size 40 x 0"},
      {"point", section + 120 + 8 * 500, std::bit_cast<uint32_t>(INFINITY), 4,
       "keyframe 0: features: keypoint 0 is not finite"},
      {"features without the flag", second + 108, 3, 4, "keyframe 1: features without the flag"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    std::string damaged = saved;
    StoreLe(damaged, c.offset, c.value, c.width);
    Reseal(damaged);
    const absl::Status status = LoadBytes(damaged);
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(std::string(status.message()), HasSubstr(c.message));
    EXPECT_THAT(std::string(status.message()), HasSubstr(path_));
  }
  // Without resealing, the checksum catches any flipped byte of the section first.
  std::string flipped = saved;
  flipped[section + 5000] ^= 0x20;
  EXPECT_THAT(std::string(LoadBytes(flipped).message()), HasSubstr("checksum mismatch"));
}

TEST_F(MapFileKeyframesTest, HeaderCountsThatCannotBeRightAreDataLoss) {
  const std::string saved = SavedBytes();
  const size_t counts = HeaderBytes() - 20;  // map version, then the keyframe count
  const struct {
    const char* what;
    size_t offset;
    uint64_t value;
    int width;
    const char* message;
  } cases[] = {
      {"keyframe count", counts + 8, 1000, 4, "1000 keyframes cannot fit in a section of"},
      {"fewer keyframes", counts + 8, 2, 4, "2 keyframes end 4920 bytes before the section"},
      {"section size", counts + 12, uint64_t{1} << 62, 8,
       "expected at least 4611686018427387904 bytes for its keyframe section"},
      {"section one byte short", counts + 12, 30920 + 120 + 4920 - 1, 8,
       "inconsistent with the file size"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    std::string damaged = saved;
    StoreLe(damaged, c.offset, c.value, c.width);
    Reseal(damaged);
    const absl::Status status = LoadBytes(damaged);
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(std::string(status.message()), HasSubstr(c.message));
  }
  // Every header byte matters.
  for (size_t offset = 0; offset < HeaderBytes(); ++offset) {
    std::string damaged = saved;
    damaged[offset] ^= 0x01;
    EXPECT_FALSE(LoadBytes(damaged).ok()) << offset;
  }
  // Truncated anywhere in the section.
  for (size_t cut : {SectionOffset() + 1, SectionOffset() + 20000, saved.size() - 9}) {
    const absl::Status status = LoadBytes(saved.substr(0, cut));
    EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
    EXPECT_THAT(std::string(status.message()), HasSubstr("truncated"));
  }
}

TEST_F(MapFileKeyframesTest, TheWriterRefusesWhatTheReaderWould) {
  ASSERT_TRUE(SaveMap(*SmallMap(), path_).ok());
  const std::string before = ReadBytes(path_);
  MapFileState state = ThreeKeyframes();
  auto bad = std::make_shared<FrameFeatures>(*state.keyframes[0].features);
  bad->points[3].y() = std::numeric_limits<float>::quiet_NaN();
  state.keyframes[2].features = bad;
  absl::Status status = SaveMap(*SmallMap(), state, path_);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
  EXPECT_THAT(std::string(status.message()),
              HasSubstr("keyframe 2: features: keypoint 3 is not finite"));
  state = ThreeKeyframes();
  state.keyframes[1].intrinsics.width = 0;
  status = SaveMap(*SmallMap(), state, path_);
  EXPECT_THAT(std::string(status.message()), HasSubstr("keyframe 1: intrinsics"));
  state = ThreeKeyframes();
  auto mismatched = std::make_shared<FrameFeatures>(*state.keyframes[0].features);
  mismatched->descriptors.pop_back();
  state.keyframes[0].features = mismatched;
  EXPECT_EQ(SaveMap(*SmallMap(), state, path_).code(), absl::StatusCode::kInvalidArgument);
  // The file that was there is untouched.
  EXPECT_TRUE(ReadBytes(path_) == before);
}

}  // namespace
}  // namespace plx

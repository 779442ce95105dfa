// The map codecs (proto/map_codec.h) and the status they carry (core/grid/map_status.h): a
// request's voxel size is core's default for 0 and otherwise held to core's range, naming the
// field; a MapStatus becomes a MapInfo field by field.
#include "proto/map_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/grid/map_status.h"
#include "core/mapping/mapper.h"

namespace plx {
namespace map_codec_test {

using ::testing::StartsWith;

std::string Message(const absl::Status& s) { return std::string(s.message()); }

TEST(MapCodecTest, ZeroVoxelSizeIsTheDefault) {
  const absl::StatusOr<float> v = VoxelSizeFromProto(0.0f, 0.04f, "voxel_size");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(*v, 0.04f);
  const absl::StatusOr<float> chosen = VoxelSizeFromProto(0.1f, 0.04f, "voxel_size");
  ASSERT_TRUE(chosen.ok()) << chosen.status();
  EXPECT_EQ(*chosen, 0.1f);
}

TEST(MapCodecTest, VoxelSizeIsHeldToCoresRange) {
  for (double edge : {kMinVoxelSize, kMaxVoxelSize}) {
    EXPECT_TRUE(VoxelSizeFromProto(static_cast<float>(edge), 0.02f, "voxel_size").ok()) << edge;
  }
  const std::vector<float> bad = {
      static_cast<float>(kMinVoxelSize) / 2, static_cast<float>(kMaxVoxelSize) * 2, -0.02f,
      std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()};
  for (float voxel : bad) {
    const absl::StatusOr<float> v = VoxelSizeFromProto(voxel, 0.02f, "options.voxel_size");
    ASSERT_FALSE(v.ok()) << voxel;
    EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(Message(v.status()),
                StartsWith("options.voxel_size: must be in [0.001, 1] metres (0 = the default)"));
  }
}

TEST(MapCodecTest, MapStatusBecomesMapInfoFieldByField) {
  MapStatus s;
  s.name = "kitchen";
  s.voxel_size = 0.03f;
  s.version = 11;
  s.bricks = 42;
  s.memory_bytes = int64_t{6} << 32;  // past 32 bits
  s.keyframes = 17;
  s.dirty = true;
  s.mapping = true;
  s.source = "tum fr1/desk, every 10th frame";
  const pb::MapInfo info = MapStatusToProto(s);
  EXPECT_EQ(info.name(), "kitchen");
  EXPECT_EQ(info.voxel_size(), 0.03f);
  EXPECT_EQ(info.version(), 11u);
  EXPECT_EQ(info.bricks(), 42u);
  EXPECT_EQ(info.memory_bytes(), uint64_t{6} << 32);
  EXPECT_EQ(info.keyframes(), 17u);
  EXPECT_TRUE(info.dirty());
  EXPECT_TRUE(info.mapping());
  EXPECT_EQ(info.source(), s.source);
  s.dirty = false;
  s.mapping = false;
  EXPECT_FALSE(MapStatusToProto(s).dirty());
  EXPECT_FALSE(MapStatusToProto(s).mapping());
}

TEST(MapStatusTest, TheGridsNumbersComeFromTheMap) {
  PlenoxelMap map(0.05f);
  map.source = "two bricks";
  ASSERT_TRUE(map.grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {1, 0, -1}}).ok());
  const MapStatus s = MapStatusOf("room", map);
  EXPECT_EQ(s.name, "room");
  EXPECT_EQ(s.voxel_size, 0.05f);
  EXPECT_EQ(s.bricks, 2);
  EXPECT_EQ(s.memory_bytes, map.grid.Memory().total_bytes());
  EXPECT_GT(s.memory_bytes, 0);
  EXPECT_EQ(s.source, "two bricks");
  // The holder's fields are its own to set.
  EXPECT_EQ(s.version, 0u);
  EXPECT_EQ(s.keyframes, 0);
  EXPECT_FALSE(s.dirty);
  EXPECT_FALSE(s.mapping);
}

}  // namespace map_codec_test
}  // namespace plx

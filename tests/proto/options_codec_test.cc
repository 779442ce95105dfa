// The stream options codecs (proto/track_codec.h, proto/integrate_codec.h): a default message
// gives core's defaults, non-zero fields override them, and every refusal is INVALID_ARGUMENT
// naming the field, at core's own limits.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "absl/strings/str_cat.h"

#include "proto/integrate_codec.h"
#include "proto/track_codec.h"

namespace plx {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string Message(const absl::Status& s) { return std::string(s.message()); }

TEST(TrackCodecTest, DefaultMessageIsCoresGaussNewtonDefaults) {
  const absl::StatusOr<TrackerOptions> o = TrackerOptionsFromProto(pb::TrackOptions(), "options");
  ASSERT_TRUE(o.ok()) << o.status();
  const TrackerOptions expected = TrackerOptionsForMode(TrackingMode::kGaussNewton);
  EXPECT_EQ(o->rays, expected.rays);
  EXPECT_EQ(o->iterations, expected.iterations);
}

TEST(TrackCodecTest, AdamModeAndOverrides) {
  pb::TrackOptions m;
  m.set_mode(pb::TrackOptions::MODE_ADAM);
  const absl::StatusOr<TrackerOptions> adam = TrackerOptionsFromProto(m, "options");
  ASSERT_TRUE(adam.ok()) << adam.status();
  EXPECT_EQ(adam->iterations, TrackerOptionsForMode(TrackingMode::kAdam).iterations);
  m.set_rays(1234);
  m.set_iterations(7);
  const absl::StatusOr<TrackerOptions> o = TrackerOptionsFromProto(m, "options");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->rays, 1234);
  EXPECT_EQ(o->iterations, 7);
}

TEST(TrackCodecTest, UnknownModeIsRefusedNamingTheField) {
  pb::TrackOptions m;
  m.set_mode(static_cast<pb::TrackOptions::Mode>(99));
  for (const char* field : {"options", "options.tracking"}) {
    const absl::StatusOr<TrackerOptions> o = TrackerOptionsFromProto(m, field);
    ASSERT_FALSE(o.ok());
    EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(Message(o.status()), StartsWith(std::string(field) + ".mode: unknown mode 99"));
  }
}

TEST(TrackCodecTest, OptionsCoreRefusesAreRefusedNamingTheMessage) {
  pb::TrackOptions m;
  m.set_rays(std::numeric_limits<uint32_t>::max());  // past int: negative, refused by core
  const absl::StatusOr<TrackerOptions> o = TrackerOptionsFromProto(m, "options.tracking");
  ASSERT_FALSE(o.ok());
  EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(o.status()), StartsWith("options.tracking: "));
}

TEST(TrackCodecTest, EveryTrackingStateHasItsWireValue) {
  EXPECT_EQ(TrackingStateToProto(TrackingState::kOk), pb::TRACKING_STATE_OK);
  EXPECT_EQ(TrackingStateToProto(TrackingState::kDegraded), pb::TRACKING_STATE_DEGRADED);
  EXPECT_EQ(TrackingStateToProto(TrackingState::kLost), pb::TRACKING_STATE_LOST);
}

constexpr float kVoxel = 0.05f;
constexpr int64_t kMaxMapBytes = int64_t{1} << 30;

TEST(IntegrateCodecTest, DefaultMessageIsCoresDefaults) {
  const absl::StatusOr<MappingSessionOptions> o =
      MappingSessionOptionsFromProto(pb::IntegrateOptions(), kVoxel, kMaxMapBytes);
  ASSERT_TRUE(o.ok()) << o.status();
  const MapperOptions mapper = MapperOptionsForVoxelSize(kVoxel);
  EXPECT_EQ(o->iterations_per_keyframe, kDefaultIterationsPerKeyframe);
  EXPECT_EQ(o->iterations_per_keyframe, MappingSessionOptions().iterations_per_keyframe);
  EXPECT_FLOAT_EQ(o->mapper.voxel_size, kVoxel);
  EXPECT_EQ(o->mapper.batch_size, mapper.batch_size);
  EXPECT_EQ(o->mapper.allocation.max_depth, mapper.allocation.max_depth);
  EXPECT_EQ(o->mapper.fusion.max_depth, mapper.fusion.max_depth);
  EXPECT_EQ(o->mapper.max_map_bytes, kMaxMapBytes);
}

TEST(IntegrateCodecTest, NonZeroFieldsOverride) {
  pb::IntegrateOptions m;
  m.set_rays_per_iteration(4096);
  m.set_iterations_per_keyframe(kMaxIterationsPerKeyframe);  // the cap itself is allowed
  m.set_max_depth(3.5);
  const absl::StatusOr<MappingSessionOptions> o =
      MappingSessionOptionsFromProto(m, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->mapper.batch_size, 4096);
  EXPECT_EQ(o->iterations_per_keyframe, kMaxIterationsPerKeyframe);
  EXPECT_FLOAT_EQ(o->mapper.allocation.max_depth, 3.5f);
  EXPECT_FLOAT_EQ(o->mapper.fusion.max_depth, 3.5f);
}

TEST(IntegrateCodecTest, IterationsPastCoresCapAreRefused) {
  pb::IntegrateOptions m;
  m.set_iterations_per_keyframe(kMaxIterationsPerKeyframe + 1);
  const absl::StatusOr<MappingSessionOptions> o =
      MappingSessionOptionsFromProto(m, kVoxel, kMaxMapBytes);
  ASSERT_FALSE(o.ok());
  EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(o.status()), StartsWith("options.iterations_per_keyframe: at most "));
  EXPECT_THAT(Message(o.status()), HasSubstr(absl::StrCat(kMaxIterationsPerKeyframe)));
}

TEST(IntegrateCodecTest, UnusableMaxDepthIsRefused) {
  for (double depth : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    pb::IntegrateOptions m;
    m.set_max_depth(depth);
    const absl::StatusOr<MappingSessionOptions> o =
        MappingSessionOptionsFromProto(m, kVoxel, kMaxMapBytes);
    ASSERT_FALSE(o.ok()) << depth;
    EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(Message(o.status()), StartsWith("options.max_depth: "));
  }
}

TEST(IntegrateCodecTest, VoxelSizeOutsideCoresRangeIsRefused) {
  for (double voxel : {kMinVoxelSize / 2, kMaxVoxelSize * 2}) {
    const absl::StatusOr<MappingSessionOptions> o = MappingSessionOptionsFromProto(
        pb::IntegrateOptions(), static_cast<float>(voxel), kMaxMapBytes);
    ASSERT_FALSE(o.ok()) << voxel;
    EXPECT_THAT(Message(o.status()), StartsWith("options: voxel size must be in [0.001, 1]"));
  }
  EXPECT_TRUE(MappingSessionOptionsFromProto(pb::IntegrateOptions(),
                                             static_cast<float>(kMinVoxelSize), kMaxMapBytes)
                  .ok());
}

}  // namespace
}  // namespace plx

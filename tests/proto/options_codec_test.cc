// The Track and Integrate codecs (proto/track_codec.h, proto/integrate_codec.h): a default
// message gives core's defaults, non-zero fields override them, every refusal is
// INVALID_ARGUMENT naming the field at core's own limits, what the CLI writes reads back as what
// it meant, and the replies carry core's results field by field. (Slam: slam_codec_test.cc.)
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/mapping/mapper.h"
#include "proto/integrate_codec.h"
#include "proto/pose_codec.h"
#include "proto/track_codec.h"

namespace plx {
namespace options_codec_test {

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

TEST(TrackCodecTest, TrackersLimitsAreCores) {
  pb::TrackOptions m;
  m.set_rays(kMaxTrackerRays);
  m.set_iterations(kMaxTrackerIterations);
  EXPECT_TRUE(TrackerOptionsFromProto(m, "options").ok());
  for (const auto& [rays, iterations] :
       {std::pair{kMaxTrackerRays + 1, 1}, std::pair{kMinTrackerRays - 1, 1},
        std::pair{kMinTrackerRays, kMaxTrackerIterations + 1}}) {
    m.set_rays(rays);
    m.set_iterations(iterations);
    const absl::StatusOr<TrackerOptions> o = TrackerOptionsFromProto(m, "options");
    ASSERT_FALSE(o.ok()) << rays << " " << iterations;
    EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(Message(o.status()), StartsWith("options: "));
  }
}

TEST(TrackCodecTest, ChosenOptionsRoundTrip) {
  for (TrackingMode mode : {TrackingMode::kGaussNewton, TrackingMode::kAdam}) {
    TrackerOptions want = TrackerOptionsForMode(mode);
    want.rays = 3000;
    want.iterations = 17;
    const pb::TrackOptions wire = TrackOptionsToProto(want, {.rays = true, .iterations = true});
    const absl::StatusOr<TrackerOptions> got = TrackerOptionsFromProto(wire, "options");
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_EQ(got->mode, mode);
    EXPECT_EQ(got->rays, 3000);
    EXPECT_EQ(got->iterations, 17);
  }
}

TEST(TrackCodecTest, UnchosenNumbersStayZeroAndBecomeTheModesDefaults) {
  TrackerOptions chosen = TrackerOptionsForMode(TrackingMode::kAdam);
  chosen.rays = 3000;
  chosen.iterations = 17;
  const pb::TrackOptions wire = TrackOptionsToProto(chosen, {.rays = false, .iterations = true});
  EXPECT_EQ(wire.mode(), pb::TrackOptions::MODE_ADAM);
  EXPECT_EQ(wire.rays(), 0u);
  EXPECT_EQ(wire.iterations(), 17u);
  const absl::StatusOr<TrackerOptions> got = TrackerOptionsFromProto(wire, "options");
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->rays, TrackerOptionsForMode(TrackingMode::kAdam).rays);
  EXPECT_EQ(TrackOptionsToProto(chosen, {}).iterations(), 0u);
}

TEST(TrackCodecTest, EveryTrackingStateRoundTrips) {
  for (TrackingState state : {TrackingState::kOk, TrackingState::kDegraded, TrackingState::kLost}) {
    EXPECT_EQ(TrackingStateFromProto(TrackingStateToProto(state)), state)
        << TrackingStateName(state);
  }
  EXPECT_FALSE(TrackingStateFromProto(pb::TRACKING_STATE_UNSPECIFIED).has_value());
  EXPECT_FALSE(TrackingStateFromProto(static_cast<pb::TrackingState>(7)).has_value());
}

TEST(TrackCodecTest, PoseEstimateCarriesTheResult) {
  TrackingResult r;
  r.pose = SE3(Eigen::Quaterniond(Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitZ())),
               Eigen::Vector3d(1.0, 2.0, -0.5));
  r.state = TrackingState::kDegraded;
  r.reason = "few valid rays";
  r.valid_rays = 812;
  const pb::PoseEstimate e = PoseEstimateToProto(r, 3.75, uint64_t{1} << 33, 4.5);
  EXPECT_EQ(e.timestamp(), 3.75);
  const absl::StatusOr<SE3> pose = PoseFromProto(e.pose(), "pose");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_TRUE(pose->translation().isApprox(r.pose.translation()));
  EXPECT_LT(pose->rotation().angularDistance(r.pose.rotation()), 1e-9);
  EXPECT_EQ(e.state(), pb::TRACKING_STATE_DEGRADED);
  EXPECT_EQ(e.reason(), "few valid rays");
  EXPECT_EQ(e.valid_rays(), 812u);
  EXPECT_EQ(e.map_version(), uint64_t{1} << 33);
  EXPECT_EQ(e.latency_ms(), 4.5);
  EXPECT_EQ(e.dropped(), 0u);  // the stream's to add
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

TEST(IntegrateCodecTest, RaysPastCoresBatchCapAreRefused) {
  pb::IntegrateOptions m;
  m.set_rays_per_iteration(kMaxBatchSize);  // the cap itself is allowed
  EXPECT_TRUE(MappingSessionOptionsFromProto(m, kVoxel, kMaxMapBytes).ok());
  m.set_rays_per_iteration(kMaxBatchSize + 1);
  const absl::StatusOr<MappingSessionOptions> o =
      MappingSessionOptionsFromProto(m, kVoxel, kMaxMapBytes);
  ASSERT_FALSE(o.ok());
  EXPECT_EQ(o.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(o.status()),
              StartsWith(absl::StrCat("options.rays_per_iteration: at most ", kMaxBatchSize)));
}

TEST(IntegrateCodecTest, OptionsRoundTrip) {
  MappingSessionOptions want;
  want.iterations_per_keyframe = 75;
  want.mapper.batch_size = 2048;
  want.mapper.allocation.max_depth = 4.25f;
  const pb::IntegrateOptions wire = IntegrateOptionsToProto(want);
  const absl::StatusOr<MappingSessionOptions> got =
      MappingSessionOptionsFromProto(wire, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->iterations_per_keyframe, 75);
  EXPECT_EQ(got->mapper.batch_size, 2048);
  EXPECT_EQ(got->mapper.allocation.max_depth, 4.25f);
  EXPECT_EQ(got->mapper.fusion.max_depth, 4.25f);
  // Core's defaults travel as themselves and read back as the defaults.
  const absl::StatusOr<MappingSessionOptions> defaults = MappingSessionOptionsFromProto(
      IntegrateOptionsToProto(MappingSessionOptions()), kVoxel, kMaxMapBytes);
  ASSERT_TRUE(defaults.ok()) << defaults.status();
  EXPECT_EQ(defaults->iterations_per_keyframe, kDefaultIterationsPerKeyframe);
  EXPECT_EQ(defaults->mapper.batch_size, MapperOptions().batch_size);
}

TEST(IntegrateCodecTest, ProgressCarriesTheSessions) {
  MappingSessionProgress p;
  p.keyframes_integrated = 6;
  p.iterations = 250;
  p.last_batch.psnr = 27.5;
  p.last_batch.depth_l1_m = 0.0125;
  const pb::MappingProgress m = MappingProgressToProto(p, "integrate-4", 3, 1.5);
  EXPECT_EQ(m.job_id(), "integrate-4");
  EXPECT_EQ(m.keyframes_integrated(), 6u);
  EXPECT_EQ(m.iterations(), 250u);
  EXPECT_EQ(m.train_psnr(), 27.5);
  EXPECT_EQ(m.train_depth_l1_m(), 0.0125);
  EXPECT_EQ(m.map_version(), 3u);
  EXPECT_EQ(m.elapsed_s(), 1.5);
  EXPECT_EQ(m.keyframes_received(), 0u);  // the stream's to add
  EXPECT_FALSE(m.done());
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

}  // namespace options_codec_test
}  // namespace plx

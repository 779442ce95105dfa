// The Slam codecs (proto/slam_codec.h): the options the CLI writes come back as the options it
// meant, a default message is core's SLAM defaults, every out-of-range field is refused as
// INVALID_ARGUMENT naming it at core's own limits, and the updates carry the tracker's result
// and the mapping job's progress field by field.
#include "proto/slam_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/mapping/mapper.h"
#include "core/mapping/mapping_session.h"
#include "core/slam/slam_coordinator.h"
#include "proto/pose_codec.h"

namespace plx {
namespace slam_codec_test {

using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr float kVoxel = 0.05f;
constexpr int64_t kMaxMapBytes = int64_t{1} << 30;

std::string Message(const absl::Status& s) { return std::string(s.message()); }

// Every field the wire carries, each away from its default.
SlamOptions ChosenOptions() {
  TrackerOptions tracker = TrackerOptionsForMode(TrackingMode::kAdam);
  tracker.rays = 2048;
  tracker.iterations = 30;
  SlamOptions s = SlamOptionsFor(kVoxel, tracker);
  s.keyframes.max_translation_m = 0.25;
  s.keyframes.max_rotation_rad = 20.0 * M_PI / 180.0;
  s.keyframes.max_unmapped_fraction = 0.4;
  s.keyframes.max_interval_s = 2.5;
  s.mapping.iterations_per_keyframe = 80;
  s.mapping.mapper.batch_size = 4096;
  s.mapping.mapper.allocation.max_depth = 6.5f;
  s.mapping.mapper.fusion.max_depth = 6.5f;
  s.max_pending_keyframes = 2;
  s.loop_closure.enabled = false;
  return s;
}

SlamOptionsFields AllFields() {
  return {.voxel_size = true,
          .tracking = {.rays = true, .iterations = true},
          .kf_translation = true,
          .kf_rotation = true,
          .kf_unmapped_fraction = true,
          .kf_interval = true,
          .iterations_per_keyframe = true,
          .rays_per_iteration = true,
          .max_depth = true,
          .max_pending_keyframes = true,
          .loop_closure = true};
}

// The settings the wire carries, compared (floats travel as float: 1e-6 relative).
void ExpectSameWireSettings(const SlamOptions& got, const SlamOptions& want) {
  EXPECT_EQ(got.tracker.mode, want.tracker.mode);
  EXPECT_EQ(got.tracker.rays, want.tracker.rays);
  EXPECT_EQ(got.tracker.iterations, want.tracker.iterations);
  EXPECT_FLOAT_EQ(got.mapping.mapper.voxel_size, want.mapping.mapper.voxel_size);
  EXPECT_NEAR(got.keyframes.max_translation_m, want.keyframes.max_translation_m, 1e-6);
  EXPECT_NEAR(got.keyframes.max_rotation_rad, want.keyframes.max_rotation_rad, 1e-6);
  EXPECT_NEAR(got.keyframes.max_unmapped_fraction, want.keyframes.max_unmapped_fraction, 1e-6);
  EXPECT_NEAR(got.keyframes.max_interval_s, want.keyframes.max_interval_s, 1e-6);
  EXPECT_EQ(got.mapping.iterations_per_keyframe, want.mapping.iterations_per_keyframe);
  EXPECT_EQ(got.mapping.mapper.batch_size, want.mapping.mapper.batch_size);
  EXPECT_FLOAT_EQ(got.mapping.mapper.allocation.max_depth,
                  want.mapping.mapper.allocation.max_depth);
  EXPECT_FLOAT_EQ(got.mapping.mapper.fusion.max_depth, want.mapping.mapper.fusion.max_depth);
  EXPECT_EQ(got.max_pending_keyframes, want.max_pending_keyframes);
  EXPECT_EQ(got.deterministic, want.deterministic);
  EXPECT_EQ(got.loop_closure.enabled, want.loop_closure.enabled);
}

TEST(SlamCodecTest, DefaultMessageIsCoresSlamDefaults) {
  const absl::StatusOr<float> voxel = SlamVoxelSizeFromProto(pb::SlamOptions());
  ASSERT_TRUE(voxel.ok()) << voxel.status();
  EXPECT_EQ(*voxel, DefaultSlamOptions().mapping.mapper.voxel_size);
  const absl::StatusOr<SlamOptions> o =
      SlamOptionsFromProto(pb::SlamOptions(), kVoxel, kMaxMapBytes);
  ASSERT_TRUE(o.ok()) << o.status();
  ExpectSameWireSettings(*o,
                         SlamOptionsFor(kVoxel, TrackerOptionsForMode(TrackingMode::kGaussNewton)));
  EXPECT_EQ(o->mapping.iterations_per_keyframe, kDefaultIterationsPerKeyframe);
  EXPECT_EQ(o->max_pending_keyframes, DefaultSlamOptions().max_pending_keyframes);
  EXPECT_EQ(o->mapping.mapper.max_map_bytes, kMaxMapBytes);
  EXPECT_FALSE(o->deterministic);
}

TEST(SlamCodecTest, ChosenOptionsRoundTrip) {
  const SlamOptions want = ChosenOptions();
  const pb::SlamOptions wire = SlamOptionsToProto(want, /*realtime=*/true, AllFields());
  EXPECT_TRUE(wire.realtime());
  EXPECT_TRUE(wire.has_max_pending_keyframes());
  const absl::StatusOr<float> voxel = SlamVoxelSizeFromProto(wire);
  ASSERT_TRUE(voxel.ok()) << voxel.status();
  EXPECT_FLOAT_EQ(*voxel, kVoxel);
  const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(wire, *voxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  ExpectSameWireSettings(*got, want);
  EXPECT_TRUE(SlamMappingOptionsChosen(wire));
  // A realtime stream is a live source: its frames never wait for mapping.
  EXPECT_TRUE(got->live_source);
  EXPECT_EQ(SplitSlamOptions(*got).tracker.max_deferred_frames, 0);
}

TEST(SlamCodecTest, LockStepWithoutABoundIgnoresTheDefaultOne) {
  pb::SlamOptions wire;
  wire.set_deterministic(true);
  const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(wire, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_TRUE(got->deterministic);
  EXPECT_FALSE(got->live_source);
  EXPECT_EQ(SplitSlamOptions(*got).gate.max_pending_keyframes, 0);
}

TEST(SlamCodecTest, LockStepRoundTrips) {
  SlamOptions want = ChosenOptions();
  want.deterministic = true;
  want.max_pending_keyframes = 0;
  const pb::SlamOptions wire = SlamOptionsToProto(want, /*realtime=*/false, AllFields());
  EXPECT_FALSE(wire.realtime());
  EXPECT_TRUE(wire.deterministic());
  const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(wire, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  ExpectSameWireSettings(*got, want);
}

TEST(SlamCodecTest, UnchosenFieldsStayZeroAndBecomeTheDefaults) {
  const SlamOptions chosen = ChosenOptions();
  const pb::SlamOptions wire = SlamOptionsToProto(chosen, /*realtime=*/false, {});
  EXPECT_EQ(wire.voxel_size(), 0.0f);
  EXPECT_EQ(wire.tracking().mode(), pb::TrackOptions::MODE_ADAM);  // the mode always goes
  EXPECT_EQ(wire.tracking().rays(), 0u);
  EXPECT_EQ(wire.tracking().iterations(), 0u);
  EXPECT_EQ(wire.kf_translation_m(), 0.0f);
  EXPECT_EQ(wire.kf_rotation_deg(), 0.0f);
  EXPECT_EQ(wire.kf_unmapped_fraction(), 0.0f);
  EXPECT_EQ(wire.kf_interval_s(), 0.0f);
  EXPECT_EQ(wire.iterations_per_keyframe(), 0u);
  EXPECT_EQ(wire.rays_per_iteration(), 0u);
  EXPECT_EQ(wire.max_depth(), 0.0f);
  EXPECT_FALSE(wire.has_max_pending_keyframes());
  EXPECT_FALSE(SlamMappingOptionsChosen(wire));
  const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(wire, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  ExpectSameWireSettings(*got, SlamOptionsFor(kVoxel, TrackerOptionsForMode(TrackingMode::kAdam)));
}

TEST(SlamCodecTest, EachMappingFieldCountsAsChosen) {
  const std::vector<std::function<void(pb::SlamOptions&)>> setters = {
      [](pb::SlamOptions& o) { o.set_iterations_per_keyframe(10); },
      [](pb::SlamOptions& o) { o.set_rays_per_iteration(512); },
      [](pb::SlamOptions& o) { o.set_max_depth(3.0f); },
  };
  for (const auto& set : setters) {
    pb::SlamOptions o;
    set(o);
    EXPECT_TRUE(SlamMappingOptionsChosen(o)) << o.ShortDebugString();
  }
  pb::SlamOptions keyframes_only;
  keyframes_only.set_kf_translation_m(0.3f);
  keyframes_only.set_max_pending_keyframes(1);
  EXPECT_FALSE(SlamMappingOptionsChosen(keyframes_only));
}

TEST(SlamCodecTest, CoresCapsThemselvesAreAllowed) {
  pb::SlamOptions o;
  o.set_iterations_per_keyframe(kMaxIterationsPerKeyframe);
  o.set_rays_per_iteration(kMaxBatchSize);
  o.set_kf_unmapped_fraction(1.0f);
  o.set_max_pending_keyframes(kMaxPendingKeyframes);
  const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(o, kVoxel, kMaxMapBytes);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->mapping.iterations_per_keyframe, kMaxIterationsPerKeyframe);
  EXPECT_EQ(got->mapping.mapper.batch_size, kMaxBatchSize);
  EXPECT_EQ(got->keyframes.max_unmapped_fraction, 1.0);
  EXPECT_EQ(got->max_pending_keyframes, kMaxPendingKeyframes);
}

struct BadField {
  std::function<void(pb::SlamOptions&)> set;
  std::string prefix;  // the message starts with it
};

TEST(SlamCodecTest, EachOutOfRangeFieldIsRefusedNamingIt) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<BadField> cases = {
      {[](pb::SlamOptions& o) { o.set_kf_translation_m(-0.1f); }, "options.kf_translation_m: "},
      {[&](pb::SlamOptions& o) { o.set_kf_rotation_deg(nan); }, "options.kf_rotation_deg: "},
      {[](pb::SlamOptions& o) { o.set_kf_unmapped_fraction(1.5f); },
       "options.kf_unmapped_fraction: "},
      {[](pb::SlamOptions& o) { o.set_kf_unmapped_fraction(-0.5f); },
       "options.kf_unmapped_fraction: "},
      {[&](pb::SlamOptions& o) { o.set_kf_interval_s(-inf); }, "options.kf_interval_s: "},
      {[&](pb::SlamOptions& o) { o.set_max_depth(inf); }, "options.max_depth: "},
      {[](pb::SlamOptions& o) { o.set_iterations_per_keyframe(kMaxIterationsPerKeyframe + 1); },
       absl::StrCat("options.iterations_per_keyframe: at most ", kMaxIterationsPerKeyframe)},
      {[](pb::SlamOptions& o) { o.set_rays_per_iteration(kMaxBatchSize + 1); },
       absl::StrCat("options.rays_per_iteration: at most ", kMaxBatchSize)},
      {[](pb::SlamOptions& o) { o.set_max_pending_keyframes(kMaxPendingKeyframes + 1); },
       absl::StrCat("options.max_pending_keyframes: must be in [0, ", kMaxPendingKeyframes)},
      {[](pb::SlamOptions& o) { o.mutable_tracking()->set_mode(pb::TrackOptions::Mode(9)); },
       "options.tracking.mode: unknown mode 9"},
      {[](pb::SlamOptions& o) { o.mutable_tracking()->set_rays(kMinTrackerRays - 1); },
       "options.tracking: rays must be in "},
      {[](pb::SlamOptions& o) {
         o.set_realtime(true);
         o.set_deterministic(true);
       },
       "options: realtime and deterministic exclude each other"},
      {[](pb::SlamOptions& o) {
         o.set_deterministic(true);
         o.set_max_pending_keyframes(1);
       },
       "options: max_pending_keyframes must be 0 with deterministic"},
  };
  for (const BadField& c : cases) {
    pb::SlamOptions o;
    c.set(o);
    const absl::StatusOr<SlamOptions> got = SlamOptionsFromProto(o, kVoxel, kMaxMapBytes);
    ASSERT_FALSE(got.ok()) << o.ShortDebugString();
    EXPECT_EQ(got.status().code(), absl::StatusCode::kInvalidArgument) << o.ShortDebugString();
    EXPECT_THAT(Message(got.status()), StartsWith(c.prefix)) << o.ShortDebugString();
  }
}

TEST(SlamCodecTest, VoxelSizeOutsideCoresRangeIsRefusedNamingIt) {
  for (float voxel : {static_cast<float>(kMinVoxelSize / 2), static_cast<float>(kMaxVoxelSize * 2),
                      -0.02f, std::numeric_limits<float>::quiet_NaN()}) {
    pb::SlamOptions o;
    o.set_voxel_size(voxel);
    const absl::StatusOr<float> got = SlamVoxelSizeFromProto(o);
    ASSERT_FALSE(got.ok()) << voxel;
    EXPECT_EQ(got.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(Message(got.status()), StartsWith("options.voxel_size: must be in [0.001, 1]"));
  }
  for (double voxel : {kMinVoxelSize, kMaxVoxelSize}) {
    pb::SlamOptions o;
    o.set_voxel_size(static_cast<float>(voxel));
    const absl::StatusOr<float> got = SlamVoxelSizeFromProto(o);
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_FLOAT_EQ(*got, static_cast<float>(voxel));
  }
}

TEST(SlamCodecTest, EveryStateRoundTrips) {
  for (SlamState state : {SlamState::kOk, SlamState::kDegraded, SlamState::kLost,
                          SlamState::kRelocalised, SlamState::kWaiting}) {
    const pb::SlamState wire = SlamStateToProto(state);
    EXPECT_NE(wire, pb::SLAM_STATE_UNSPECIFIED) << SlamStateName(state);
    EXPECT_EQ(SlamStateFromProto(wire), state) << SlamStateName(state);
  }
  EXPECT_EQ(SlamStateToProto(SlamState::kRelocalised), pb::SLAM_STATE_RELOCALISED);
  EXPECT_EQ(SlamStateToProto(SlamState::kWaiting), pb::SLAM_STATE_WAITING);
  EXPECT_FALSE(SlamStateFromProto(pb::SLAM_STATE_UNSPECIFIED).has_value());
  EXPECT_FALSE(SlamStateFromProto(static_cast<pb::SlamState>(42)).has_value());
}

SlamMapperProgress Progress() {
  SlamMapperProgress p;
  p.keyframes = 7;
  p.keyframes_integrated = 5;
  p.pending_keyframes = 2;
  p.mapping_iterations = 321;
  p.map_version = 9;
  p.map_bytes = int64_t{5} << 32;  // past 32 bits: the wire's uint64 keeps it
  return p;
}

TEST(SlamCodecTest, MappingCarriesTheJobsProgress) {
  const pb::SlamMapping m = SlamMappingToProto(Progress(), "slam-3", 2, true);
  EXPECT_EQ(m.job_id(), "slam-3");
  EXPECT_EQ(m.keyframes(), 7u);
  EXPECT_EQ(m.keyframes_integrated(), 5u);
  EXPECT_EQ(m.iterations(), 321u);
  EXPECT_EQ(m.map_version(), 9u);
  EXPECT_EQ(m.map_bytes(), uint64_t{5} << 32);
  EXPECT_EQ(m.streams(), 2u);
  EXPECT_TRUE(m.finished());
  EXPECT_FALSE(SlamMappingToProto(Progress(), "slam-3", 1, false).finished());
}

TEST(SlamCodecTest, MappingCarriesTheLoopClosureCounts) {
  SlamMapperProgress p = Progress();
  p.loops.accepted = 3;
  p.loops.rejected = 2;
  p.loops.corrections = 3;
  p.loops.in_place = 2;
  p.loops.last_solve_ms = 4.5;
  const pb::SlamMapping m = SlamMappingToProto(p, "slam-3", 1, false);
  EXPECT_EQ(m.loops_accepted(), 3u);
  EXPECT_EQ(m.loops_rejected(), 2u);
  EXPECT_EQ(m.corrections(), 3u);
  EXPECT_EQ(m.corrections_in_place(), 2u);
  EXPECT_DOUBLE_EQ(m.last_solve_ms(), 4.5);
}

TEST(SlamCodecTest, ACorrectionRoundTripsWithEveryKeyframe) {
  SlamCorrection c;
  c.generation = 2;
  c.map_version = 17;
  const SE3 lift(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0.5, 0));
  c.before = {SE3::Identity(), SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 0))};
  c.after = {c.before[0], lift * c.before[1]};  // keyframe 0 did not move: it is sent too
  c.max_shift_m = 0.5;
  c.loops = 1;
  SlamFrameResult result;
  result.correction = std::make_shared<SlamCorrection>(c);
  result.frame_change = lift;
  result.correction_generation = 2;
  const pb::SlamUpdate update = SlamUpdateToProto(result, 4, 1.0, 0, pb::SlamMapping());
  EXPECT_EQ(update.correction_generation(), 2u);
  ASSERT_TRUE(update.has_correction());
  EXPECT_NEAR(update.correction().camera_new_t_old().ty(), 0.5, 1e-12);
  ASSERT_EQ(update.correction().keyframes_size(), 2);
  const absl::StatusOr<SlamCorrection> back = SlamCorrectionFromProto(update.correction());
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->generation, 2);
  EXPECT_EQ(back->map_version, 17);
  EXPECT_EQ(back->loops, 1);
  EXPECT_DOUBLE_EQ(back->max_shift_m, 0.5);
  ASSERT_EQ(back->after.size(), 2u);
  EXPECT_TRUE(back->after[1].translation().isApprox(Eigen::Vector3d(1, 0.5, 0)));
  // Without a correction, none is sent.
  EXPECT_FALSE(SlamUpdateToProto(SlamFrameResult{}, 5, 1.0, 0, pb::SlamMapping())
                   .has_correction());
}

TEST(SlamCodecTest, UpdateCarriesTheFramesResult) {
  SlamFrameResult r;
  r.timestamp = 17.25;
  r.pose = SE3(Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY())),
               Eigen::Vector3d(0.5, -1.0, 2.0));
  r.state = SlamState::kRelocalised;
  r.reason = "relocalised from keyframe 3";
  r.keyframe = true;
  r.map_version = 12;
  r.tracking.valid_rays = 1500;
  const pb::SlamUpdate u =
      SlamUpdateToProto(r, 41, 12.5, 3, SlamMappingToProto(Progress(), "slam-3", 1, false));
  EXPECT_EQ(u.frame(), 41u);
  EXPECT_EQ(u.timestamp(), 17.25);
  const absl::StatusOr<SE3> pose = PoseFromProto(u.pose(), "pose");
  ASSERT_TRUE(pose.ok()) << pose.status();
  EXPECT_TRUE(pose->translation().isApprox(r.pose.translation()));
  EXPECT_LT(pose->rotation().angularDistance(r.pose.rotation()), 1e-9);
  EXPECT_EQ(u.state(), pb::SLAM_STATE_RELOCALISED);
  EXPECT_EQ(u.reason(), r.reason);
  EXPECT_TRUE(u.keyframe());
  EXPECT_EQ(u.map_version(), 12u);
  EXPECT_EQ(u.latency_ms(), 12.5);
  EXPECT_EQ(u.dropped(), 3u);
  EXPECT_EQ(u.valid_rays(), 1500u);
  EXPECT_EQ(u.mapping().keyframes(), 7u);
  EXPECT_FALSE(u.done());
  EXPECT_EQ(u.segment(), 0u);
  EXPECT_FALSE(u.new_segment());
  EXPECT_FALSE(u.has_main_t_segment()) << "set only on the frame that joins a segment";
}

TEST(SlamCodecTest, UpdateSaysWhichSegmentThePoseIsInAndHowASegmentJoined) {
  SlamFrameResult started;
  started.segment = 2;
  started.new_segment = true;
  started.keyframe = true;
  pb::SlamUpdate u =
      SlamUpdateToProto(started, 5, 1.0, 0, SlamMappingToProto(Progress(), "slam-3", 1, false));
  EXPECT_EQ(u.segment(), 2u);
  EXPECT_TRUE(u.new_segment());
  EXPECT_FALSE(u.has_main_t_segment());

  SlamFrameResult joined;
  joined.state = SlamState::kRelocalised;
  joined.main_T_segment = SE3(Eigen::Quaterniond(Eigen::AngleAxisd(1.2, Eigen::Vector3d::UnitZ())),
                              Eigen::Vector3d(0.3, 0.0, -4.0));
  u = SlamUpdateToProto(joined, 9, 1.0, 0, SlamMappingToProto(Progress(), "slam-3", 1, false));
  EXPECT_EQ(u.segment(), 0u);
  EXPECT_FALSE(u.new_segment());
  ASSERT_TRUE(u.has_main_t_segment());
  const absl::StatusOr<SE3> t = PoseFromProto(u.main_t_segment(), "main_T_segment");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_TRUE(t->translation().isApprox(joined.main_T_segment->translation()));
  EXPECT_LT(t->rotation().angularDistance(joined.main_T_segment->rotation()), 1e-9);
}

TEST(SlamCodecTest, DoneCarriesOnlyTheMapping) {
  const pb::SlamUpdate done = SlamDoneToProto(SlamMappingToProto(Progress(), "slam-3", 0, true));
  EXPECT_TRUE(done.done());
  EXPECT_FALSE(done.has_pose());
  EXPECT_EQ(done.frame(), 0u);
  EXPECT_EQ(done.state(), pb::SLAM_STATE_UNSPECIFIED);
  EXPECT_TRUE(done.mapping().finished());
  EXPECT_EQ(done.mapping().keyframes_integrated(), 5u);
}

}  // namespace slam_codec_test
}  // namespace plx

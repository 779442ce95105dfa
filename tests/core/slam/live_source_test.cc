// A live source (SlamOptions::live_source: a live camera, a realtime replay, a daemon stream
// with realtime) never makes a frame wait for mapping: a keyframe mapping has no room for stays
// deferred for as long as mapping is behind. A replay as fast as the engine goes takes it after
// SlamTrackerOptions::max_deferred_frames, and that frame waits. Mapping is never stepped after
// keyframe 0 here, so it stays behind for the whole run, the same every time.
#include <gtest/gtest.h>

#include <memory>
#include <optional>
#include <string>

#include "core/cpu/cpu_backend.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "tests/core/slam/run_mapping_out.h"
#include "tests/core/slam/slam_test_options.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

constexpr int kFrames = 60;

struct BehindRun {
  int keyframes_after_first = 0;  // keyframes taken after keyframe 0
  int deferred = 0;               // frames that deferred one
  int overdue = 0;                // keyframes taken after max_deferred_frames (frame waits)
};

BehindRun RunWithMappingBehind(const InMemoryDataset& room, bool live_source) {
  const PinholeIntrinsics k = room.calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  SlamOptions o = testing::SmallLockStepSlamOptions();
  o.deterministic = false;
  o.live_source = live_source;
  o.initial_pose = *room.ground_truth(0);
  EXPECT_TRUE(ValidateSlamOptions(o).ok());
  const SlamSplitOptions split = SplitSlamOptions(o);
  SlamCoordinator map(split.mapper, split.gate);
  SlamTracker camera(split.tracker, backend.get());
  EXPECT_TRUE(map.StartMapper(backend.get()).ok());
  BehindRun run;
  int segment = 0;
  for (int i = 0; i < kFrames; ++i) {
    absl::StatusOr<SlamFrameResult> r =
        camera.Track(room.frames()[i], k, std::nullopt, map.View(segment));
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return run;
    EXPECT_TRUE(map.Accept(room.frames()[i], k, &*r, &segment).ok());
    if (i == 0) {
      testing::RunMappingOut(map);  // keyframe 0 is mapped; nothing after it is
      continue;
    }
    run.keyframes_after_first += r->keyframe;
    run.deferred += r->reason.find("keyframe deferred") != std::string::npos;
    run.overdue += r->reason.find("waits for mapping)") != std::string::npos;
  }
  return run;
}

TEST(LiveSourceTest, AKeyframeStaysDeferredWhileMappingIsBehindAndNoFrameWaits) {
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(160, 120, kFrames);
  ASSERT_NE(room, nullptr);
  const BehindRun live = RunWithMappingBehind(*room, /*live_source=*/true);
  const BehindRun replay = RunWithMappingBehind(*room, /*live_source=*/false);
  // The first keyframe after keyframe 0 fits the bound (one may wait); the rest are deferred.
  EXPECT_EQ(live.keyframes_after_first, 1);
  EXPECT_EQ(live.overdue, 0);
  EXPECT_GE(live.deferred, SlamTrackerOptions().max_deferred_frames + 1);
  // The replay takes one after max_deferred_frames deferred frames, and that frame waits.
  EXPECT_GE(replay.overdue, 1);
  EXPECT_EQ(replay.keyframes_after_first, 1 + replay.overdue);
}

TEST(LiveSourceTest, TheOdometryCarriesTheCameraUntilTheFirstVersionHoweverLongItTakes) {
  // Keyframe 0 is accepted and never integrated here: a replay's camera waits for its version
  // after a second or once it leaves keyframe 0's view (SlamMapSegmentTest), a live one is
  // carried on (DEGRADED, the odometry's pose, never a keyframe).
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(160, 120, 24);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  SlamOptions o = testing::SmallLockStepSlamOptions();
  o.deterministic = false;
  o.live_source = true;
  o.initial_pose = *room->ground_truth(0);
  const SlamSplitOptions split = SplitSlamOptions(o);
  SlamCoordinator map(split.mapper, split.gate);
  SlamTracker camera(split.tracker, backend.get());
  int segment = 0;
  for (int i = 0; i < room->size(); ++i) {
    RgbdFrame frame = room->frames()[i];
    frame.timestamp = 0.1 * i;  // 2.3 s in all, ~35 cm and well out of keyframe 0's view
    const SlamMapView view = map.View(segment);
    ASSERT_EQ(view.map, nullptr);
    ASSERT_FALSE(camera.NeedsVersion(view)) << "frame " << i;
    absl::StatusOr<SlamFrameResult> r = camera.Track(frame, k, std::nullopt, view);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_TRUE(map.Accept(frame, k, &*r, &segment).ok());
    if (i == 0) continue;
    EXPECT_EQ(r->state, SlamState::kDegraded) << "frame " << i << ": " << r->reason;
    EXPECT_EQ(r->source, PoseSource::kOdometry);
    EXPECT_FALSE(r->keyframe);
    // The odometry alone drifts ~1 mm per frame here (measured: 2.3 cm after ~35 cm): what
    // the carry costs until the map tracker takes over.
    EXPECT_LT((r->pose.translation() - room->ground_truth(i)->translation()).norm(), 0.03)
        << "frame " << i;
  }
}

}  // namespace
}  // namespace plx

// Two cameras in one map: each has its own SlamTracker, their keyframes go to one map's
// SlamCoordinator (the daemon's wiring for several Slam streams on a map). Lock-step mapping
// after each keyframe, so the numbers are the same run to run.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/eval/trajectory_metrics.h"
#include "core/slam/map_segment_poses.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "tests/core/slam/run_mapping_out.h"
#include "tests/core/slam/slam_test_options.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace multi_camera_test {

SlamOptions TestOptions() { return testing::SmallLockStepSlamOptions(); }

// The map's coordinator with its mapper started on `backend` (lock-step: the options are
// deterministic).
std::unique_ptr<SlamCoordinator> StartedCoordinator(const SlamOptions& options, Backend* backend) {
  const SlamSplitOptions split = SplitSlamOptions(options);
  auto coordinator = std::make_unique<SlamCoordinator>(split.mapper, split.gate);
  const absl::Status started = coordinator->StartMapper(backend);
  EXPECT_TRUE(started.ok()) << started;
  return started.ok() ? std::move(coordinator) : nullptr;
}

double AteRmse(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& gt) {
  absl::StatusOr<TrajectoryEvalResult> eval = EvaluateTrajectory(estimate, gt);
  EXPECT_TRUE(eval.ok()) << eval.status();
  return eval.ok() ? eval->ate.translation_m.rmse : 1e9;
}

// One camera's frame: tracked in the map's view; a keyframe is handed to the coordinator,
// whose mapper then runs to the end of its work (lock-step).
SlamFrameResult Process(SlamTracker& tracker, SlamCoordinator& coordinator, const RgbdFrame& frame,
                        const PinholeIntrinsics& k) {
  absl::StatusOr<SlamFrameResult> r = tracker.Track(frame, k, std::nullopt, coordinator.View());
  EXPECT_TRUE(r.ok()) << r.status();
  if (!r.ok()) return SlamFrameResult();
  if (r->keyframe) {
    EXPECT_TRUE(coordinator.AddKeyframe(frame, r->pose, k, r->features).ok());
    testing::RunMappingOut(coordinator, SlamStepMode::kMap);
    EXPECT_TRUE(coordinator.MayCameraProceed()) << "lock-step mapping left work";
  }
  return *r;
}

// 160x120, 90 frames of the circling path, one map's coordinator (mapping on its own backend)
// and the trackers' backend: two cameras' room.
class SlamTwoCameraRoomTest : public ::testing::Test {
 protected:
  void SetUp() override {
    room_ = testing::MakeSyntheticRoom(160, 120, 90);
    ASSERT_NE(room_, nullptr);
    k_ = room_->calibration().pinhole;
    map_ = StartedCoordinator(options_, mapping_.get());
    ASSERT_NE(map_, nullptr);
  }
  // A camera starting at frame `start`'s true pose (none: no initial pose, the identity).
  std::unique_ptr<SlamTracker> Camera(std::optional<int> start) const {
    SlamTrackerOptions o = SplitSlamOptions(options_).tracker;
    if (start) o.initial_pose = *room_->ground_truth(*start);
    return std::make_unique<SlamTracker>(o, tracking_.get());
  }

  const SlamOptions options_ = TestOptions();
  std::unique_ptr<Backend> tracking_ = MakeCpuBackend(2);
  std::unique_ptr<Backend> mapping_ = MakeCpuBackend(1);
  std::unique_ptr<InMemoryDataset> room_;
  PinholeIntrinsics k_;
  std::unique_ptr<SlamCoordinator> map_;
};

TEST_F(SlamTwoCameraRoomTest, TwoCamerasTrackInOneGrowingMap) {
  // 160x120, 90 frames of the circling path. Camera A walks it from frame 0 to 89. Once A has
  // mapped frames 0-40, camera B joins at frame 40's place (its initial pose, as a client
  // would give it) and walks back to frame 0 while A goes on: B's frames interleave with A's.
  const InMemoryDataset* room = room_.get();
  const PinholeIntrinsics& k = k_;
  SlamCoordinator* map = map_.get();
  const std::unique_ptr<SlamTracker> a_camera = Camera(0);
  // B joins a map that has versions: its first frame relocalises from its initial pose.
  const std::unique_ptr<SlamTracker> b_camera = Camera(40);
  SlamTracker& a = *a_camera;
  SlamTracker& b = *b_camera;

  std::vector<StampedPose> a_trajectory, a_truth, b_trajectory, b_truth;
  int b_keyframes = 0;
  for (int i = 0; i < room->size(); ++i) {
    const RgbdFrame& fa = room->frames()[i];
    SlamFrameResult ra = Process(a, *map, fa, k);
    EXPECT_NE(ra.state, SlamState::kLost) << "camera A, frame " << i;
    a_trajectory.push_back({fa.timestamp, ra.pose});
    a_truth.push_back({fa.timestamp, *fa.ground_truth});
    const int j = i - 40;  // B's frame count
    if (j < 0 || j > 40) continue;
    // B walks frames 40, 39, ..., 0, stamped with increasing times like a live camera.
    RgbdFrame fb = room->frames()[40 - j];
    fb.timestamp = room->timestamp(40 + j);
    const SE3 truth = *fb.ground_truth;
    SlamFrameResult rb = Process(b, *map, fb, k);
    if (j == 0) {
      EXPECT_EQ(rb.state, SlamState::kRelocalised) << rb.reason;
    } else {
      EXPECT_NE(rb.state, SlamState::kLost) << "camera B, frame " << j;
    }
    b_keyframes += rb.keyframe;
    b_trajectory.push_back({fb.timestamp, rb.pose});
    b_truth.push_back({fb.timestamp, truth});
  }
  testing::RunMappingOut(*map, SlamStepMode::kFinish);

  const double ate_a = AteRmse(a_trajectory, a_truth);
  const double ate_b = AteRmse(b_trajectory, b_truth);
  const SlamMapperProgress p = map->progress();
  std::printf("camera A ATE %.2f mm, camera B ATE %.2f mm; %d keyframes (%d from B)\n",
              1000 * ate_a, 1000 * ate_b, p.keyframes, b_keyframes);
  // Single-camera SLAM on this path: 5.4 mm (slam_session_test); B only revisits A's map.
  EXPECT_LE(ate_a, 0.006);
  EXPECT_LE(ate_b, 0.006);
  // B walks where A's keyframes already are: the policy checks every keyframe of the map.
  EXPECT_LE(b_keyframes, 1);
  EXPECT_EQ(p.keyframes_integrated, p.keyframes);
  EXPECT_EQ(a.counts().frames, 90);
  EXPECT_EQ(b.counts().frames, 41);
  EXPECT_EQ(p.pending_keyframes, 0);
  EXPECT_TRUE(p.idle);
  EXPECT_EQ(static_cast<int>(map->keyframe_poses().size()), p.keyframes);
}

// One camera's frame as the daemon's stream handles it: tracked in its segment's view, then
// accepted as `camera`'s (a keyframe, a new segment or a segment's join), the mapper run to
// the end of its work.
SlamFrameResult ProcessInSegments(SlamTracker& tracker, SlamCoordinator& coordinator,
                                  const RgbdFrame& frame, const PinholeIntrinsics& k,
                                  int* segment, int camera) {
  absl::StatusOr<SlamFrameResult> r =
      tracker.Track(frame, k, std::nullopt, coordinator.View(*segment));
  EXPECT_TRUE(r.ok()) << r.status();
  if (!r.ok()) return SlamFrameResult();
  absl::StatusOr<bool> queued = coordinator.Accept(frame, k, &*r, segment, camera);
  EXPECT_TRUE(queued.ok()) << queued.status();
  if (queued.ok() && *queued) testing::RunMappingOut(coordinator, SlamStepMode::kMap);
  return *r;
}

TEST_F(SlamTwoCameraRoomTest, ASecondCameraStartingSomewhereUnknownEndsInTheFirstOnesFrame) {
  // Camera A walks the circling path from frame 0 (its start is the map's frame). Camera B
  // starts at the same time at frame 89's place (the far side of the circle), with no initial
  // pose (its identity means nothing in A's frame), and walks back towards frame 0 while A
  // walks on: B is lost to the map (or in a segment of its own) until it sees a place A
  // mapped, then joins the map. Every pose B reported, mapped into the main map, must be in
  // A's frame.
  constexpr int kBStart = 89;
  const InMemoryDataset* room = room_.get();
  const PinholeIntrinsics& k = k_;
  SlamCoordinator* map = map_.get();
  const std::unique_ptr<SlamTracker> a_camera = Camera(0);
  const std::unique_ptr<SlamTracker> b_camera = Camera(std::nullopt);
  SlamTracker& a = *a_camera;
  SlamTracker& b = *b_camera;
  ASSERT_GT((room->ground_truth(kBStart)->translation() -
             room->ground_truth(0)->translation()).norm(), 0.5);

  int a_segment = 0, b_segment = 0;
  std::vector<SlamFrameResult> b_results;
  std::vector<StampedPose> a_trajectory, a_truth, b_truth;
  for (int i = 0; i < room->size(); ++i) {
    const RgbdFrame& fa = room->frames()[i];
    const SlamFrameResult ra = ProcessInSegments(a, *map, fa, k, &a_segment, 0);
    a_trajectory.push_back({fa.timestamp, ra.pose});
    a_truth.push_back({fa.timestamp, *fa.ground_truth});
    if (i > kBStart) continue;
    RgbdFrame fb = room->frames()[kBStart - i];
    fb.timestamp = room->timestamp(i);
    const SE3 truth = *fb.ground_truth;
    fb.ground_truth.reset();
    SlamFrameResult rb = ProcessInSegments(b, *map, fb, k, &b_segment, 1);
    rb.timestamp = fb.timestamp;
    b_results.push_back(rb);
    b_truth.push_back({fb.timestamp, truth});
  }
  testing::RunMappingOut(*map, SlamStepMode::kFinish);
  EXPECT_EQ(a_segment, 0);
  EXPECT_EQ(b_segment, 0) << "camera B never joined the map";
  // B's poses from the frame it joined on (relocalised into the map, or its segment joined).
  int joined_at = -1;
  for (size_t j = 0; j < b_results.size() && joined_at < 0; ++j) {
    if (b_results[j].segment == 0 && (b_results[j].state == SlamState::kRelocalised ||
                                      b_results[j].main_T_segment)) {
      joined_at = static_cast<int>(j);
    }
  }
  ASSERT_GE(joined_at, 0);
  const std::vector<StampedPose> b_in_map = PosesInMainMap(b_results);
  // And before it, the frames B tracked in a segment of its own (mapped by the join's
  // main_T_segment); its LOST frames have no pose to score.
  std::vector<StampedPose> b_after, b_after_truth;
  int in_segment = 0;
  for (size_t j = 0; j < b_in_map.size(); ++j) {
    if (static_cast<int>(j) < joined_at && b_results[j].segment == 0) continue;
    in_segment += static_cast<int>(j) < joined_at;
    b_after.push_back(b_in_map[j]);
    b_after_truth.push_back(b_truth[j]);
  }
  const double ate_a = AteRmse(a_trajectory, a_truth);
  const double ate_b = AteRmse(b_after, b_after_truth);
  std::printf("camera B joined on its frame %d (%d frames in a segment before); ATE (no "
              "alignment) A %.2f mm, B %.2f mm\n",
              joined_at, in_segment, 1000 * ate_a, 1000 * ate_b);
  // One frame of reference: each camera within a centimetre of the truth, unaligned.
  EXPECT_LE(ate_a, 0.01);
  EXPECT_LE(ate_b, 0.01);
}

TEST(SlamMultiCameraTest, BootstrapNeedsEnoughDepth) {
  // The minimum: 30 % of the pixels with depth in range, and 256 pixels.
  DepthImage depth(100, 10, 1, 0.0f);
  BootstrapDepth d = CountBootstrapDepth(depth, 10.0f);
  EXPECT_EQ(d.valid, 0);
  EXPECT_EQ(d.needed, 300);
  EXPECT_FALSE(d.enough());
  for (int i = 0; i < 300; ++i) depth.data[i] = 1.0f;
  depth.data[300] = 12.0f;   // out of range
  depth.data[301] = NAN;     // never valid
  depth.data[302] = -1.0f;
  EXPECT_TRUE(CountBootstrapDepth(depth, 10.0f).enough());
  EXPECT_EQ(CountBootstrapDepth(depth, 10.0f).valid, 300);
  EXPECT_FALSE(CountBootstrapDepth(depth, 0.5f).enough());
  // A thumbnail: the absolute floor.
  EXPECT_EQ(CountBootstrapDepth(DepthImage(20, 15, 1, 1.0f), 10.0f).needed, 256);
  EXPECT_FALSE(CountBootstrapDepth(DepthImage(20, 15, 1, 0.0f), 10.0f).enough());
}

TEST(SlamMultiCameraTest, AWaitingCameraJoinsTheMapAnotherBootstrapped) {
  // Camera A comes first but sees too little depth (20 % of the rows): WAITING, nothing
  // accepted. Camera B bootstraps the map; A's next frame, with depth, joins it (relocalises
  // from its initial pose) instead of bootstrapping a second keyframe 0.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(160, 120, 12);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const SlamOptions options = TestOptions();
  std::unique_ptr<SlamCoordinator> map = StartedCoordinator(options, backend.get());
  ASSERT_NE(map, nullptr);
  SlamTrackerOptions a_options = SplitSlamOptions(options).tracker;
  a_options.initial_pose = *room->ground_truth(2);
  SlamTrackerOptions b_options = SplitSlamOptions(options).tracker;
  b_options.initial_pose = *room->ground_truth(0);
  SlamTracker a(a_options, backend.get());
  SlamTracker b(b_options, backend.get());

  RgbdFrame sparse = room->frames()[2];
  for (int v = sparse.depth.height / 5; v < sparse.depth.height; ++v) {
    for (int u = 0; u < sparse.depth.width; ++u) *sparse.depth.pixel(u, v) = 0.0f;
  }
  const SlamFrameResult waiting = Process(a, *map, sparse, k);
  EXPECT_EQ(waiting.state, SlamState::kWaiting) << waiting.reason;
  EXPECT_FALSE(waiting.keyframe);
  EXPECT_EQ(waiting.pose.matrix(), room->ground_truth(2)->matrix());
  EXPECT_TRUE(map->View().accepted_keyframes.empty());

  const SlamFrameResult first = Process(b, *map, room->frames()[0], k);
  EXPECT_TRUE(first.keyframe);
  EXPECT_EQ(first.state, SlamState::kOk);
  const SlamFrameResult joined = Process(a, *map, room->frames()[3], k);
  EXPECT_EQ(joined.state, SlamState::kRelocalised) << joined.reason;
  EXPECT_FALSE(joined.keyframe && joined.keyframes == 1) << "a second keyframe 0";
  EXPECT_LT((joined.pose.translation() - room->ground_truth(3)->translation()).norm(), 0.02);
  EXPECT_EQ(a.counts().waiting, 1);
  EXPECT_EQ(a.counts().relocalised, 1);
  EXPECT_EQ(a.counts().frames, 2);
  EXPECT_EQ(map->progress().keyframes, 1 + static_cast<int>(joined.keyframe));
}

TEST(SlamMultiCameraTest, TrackerRefusesAFrameBeforeTheFirstVersion) {
  // A second camera whose first frame comes while the map has accepted its first keyframe but
  // not published it (here: its mapper has not even started, as in the daemon before the
  // job's first task): it is told so, not bootstrapped as a second keyframe 0.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(64, 48, 2);
  ASSERT_NE(room, nullptr);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  const SlamSplitOptions split = SplitSlamOptions(TestOptions());
  SlamCoordinator map(split.mapper, split.gate);
  const PinholeIntrinsics& k = room->calibration().pinhole;
  ASSERT_TRUE(map.AddKeyframe(room->frames()[0], SE3::Identity(), k).ok());
  const SlamMapView view = map.View();
  ASSERT_EQ(view.map, nullptr);
  ASSERT_EQ(view.accepted_keyframes.size(), 1u);
  SlamTracker tracker(split.tracker, backend.get());
  EXPECT_TRUE(tracker.NeedsVersion(view));
  absl::StatusOr<SlamFrameResult> r = tracker.Track(room->frames()[1], k, std::nullopt, view);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition) << r.status();
  EXPECT_EQ(tracker.frames(), 0) << "a refused frame changes nothing";
}

TEST(SlamMultiCameraTest, AKeyframeWaitingForMappingDefersTheNextOneInsteadOfStallingTheCamera) {
  // Concurrent mode's bound (max_pending_keyframes 1): while a keyframe waits for integration,
  // a frame the policy would take is tracked as usual but not handed over (so its caller never
  // waits for mapping); once mapping catches up, the next such frame is taken. Mapping is
  // stepped by hand here, so "behind" is exact.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(160, 120, 90);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> tracking = MakeCpuBackend(2);
  std::unique_ptr<Backend> mapping = MakeCpuBackend(1);
  SlamOptions options = TestOptions();
  options.deterministic = false;
  options.max_pending_keyframes = 1;
  const SlamSplitOptions split = SplitSlamOptions(options);
  ASSERT_EQ(split.tracker.max_pending_keyframes, 1);
  SlamCoordinator map(split.mapper, split.gate);
  ASSERT_TRUE(map.StartMapper(mapping.get()).ok());
  SlamTrackerOptions tracker_options = split.tracker;
  tracker_options.initial_pose = *room->ground_truth(0);
  SlamTracker camera(tracker_options, tracking.get());

  auto track = [&](int i) {
    absl::StatusOr<SlamFrameResult> r =
        camera.Track(room->frames()[i], k, std::nullopt, map.View());
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return SlamFrameResult();
    EXPECT_NE(r->state, SlamState::kLost) << "frame " << i << ": " << r->reason;
    if (r->keyframe) {
      EXPECT_TRUE(map.AddKeyframe(room->frames()[i], r->pose, k, r->features).ok());
    }
    return *r;
  };
  ASSERT_TRUE(track(0).keyframe);
  testing::RunMappingOut(map, SlamStepMode::kMap);

  // Up to the next keyframe, with mapping kept up to date. Its frames started the map tracker
  // at the odometry's pose: half the 8 iterations.
  int i = 1;
  for (; i < 40; ++i) {
    const SlamFrameResult r = track(i);
    if (r.state == SlamState::kOk) {
      EXPECT_LE(r.tracking.iterations, 4) << "frame " << i;
    }
    if (r.keyframe) break;
    testing::RunMappingOut(map, SlamStepMode::kMap);
  }
  ASSERT_LT(i, 40) << "no second keyframe on the path";
  ASSERT_EQ(map.progress().pending_keyframes, 1);
  EXPECT_TRUE(map.MayCameraProceed()) << "one pending keyframe is within the bound";

  // Mapping stalls: the camera goes on without a keyframe, deferring those it would take.
  int deferred = 0;
  const int stalled_until = i + 20;
  for (++i; i < stalled_until; ++i) {
    const SlamFrameResult r = track(i);
    EXPECT_FALSE(r.keyframe) << "frame " << i;
    deferred += r.reason.find("keyframe deferred") != std::string::npos;
  }
  EXPECT_GE(deferred, 1) << "20 frames of the circle move the camera past the policy's bounds";
  EXPECT_EQ(map.progress().pending_keyframes, 1);

  // Mapping catches up: the camera, far from every keyframe by now, takes the next frame.
  testing::RunMappingOut(map, SlamStepMode::kMap);
  const SlamFrameResult next = track(i);
  EXPECT_TRUE(next.keyframe) << next.reason;
}

TEST(SlamMultiCameraTest, AKeyframeDeferredTooLongIsTakenAndTheCameraWaitsForMapping) {
  // A mapper that never catches up (a starved thread): without a bound the camera would go on
  // deferring for the whole run, tracking on the odometry into space nothing maps.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(160, 120, 90);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> tracking = MakeCpuBackend(2);
  std::unique_ptr<Backend> mapping = MakeCpuBackend(1);
  SlamOptions options = TestOptions();
  options.deterministic = false;
  options.max_pending_keyframes = 1;
  const SlamSplitOptions split = SplitSlamOptions(options);
  const int bound = split.tracker.max_deferred_frames;
  ASSERT_GT(bound, 0);
  SlamCoordinator map(split.mapper, split.gate);
  ASSERT_TRUE(map.StartMapper(mapping.get()).ok());
  SlamTrackerOptions tracker_options = split.tracker;
  tracker_options.initial_pose = *room->ground_truth(0);
  SlamTracker camera(tracker_options, tracking.get());

  // Keyframe 0 mapped, then nothing is integrated again.
  int keyframes = 0, deferred_in_a_row = 0;
  std::optional<int> forced_at;
  for (int i = 0; i < static_cast<int>(room->frames().size()) && !forced_at; ++i) {
    absl::StatusOr<SlamFrameResult> r =
        camera.Track(room->frames()[i], k, std::nullopt, map.View());
    ASSERT_TRUE(r.ok()) << r.status();
    const bool deferred = r->reason.find("keyframe deferred") != std::string::npos;
    if (r->keyframe) {
      ASSERT_TRUE(map.AddKeyframe(room->frames()[i], r->pose, k, r->features).ok());
      if (++keyframes == 1) testing::RunMappingOut(map, SlamStepMode::kMap);
      if (keyframes > 2) forced_at = i;
    }
    if (keyframes == 2 && !r->keyframe) {
      ASSERT_TRUE(deferred || deferred_in_a_row == 0) << "frame " << i << ": " << r->reason;
    }
    deferred_in_a_row = deferred ? deferred_in_a_row + 1 : 0;
    if (forced_at) {
      EXPECT_EQ(deferred_in_a_row, 0);
      EXPECT_NE(r->reason.find("waits for mapping"), std::string::npos) << r->reason;
    } else {
      EXPECT_LE(deferred_in_a_row, bound) << "frame " << i;
    }
  }
  ASSERT_TRUE(forced_at.has_value()) << "the room's frames never outran the bound";
  // Two keyframes wait now: over the gate's bound, so the caller holds the camera.
  EXPECT_EQ(map.progress().pending_keyframes, 2);
  EXPECT_FALSE(map.MayCameraProceed());
  testing::RunMappingOut(map, SlamStepMode::kMap);
  EXPECT_TRUE(map.MayCameraProceed());
}

}  // namespace multi_camera_test
}  // namespace plx

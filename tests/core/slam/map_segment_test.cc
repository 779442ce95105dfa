// Map segments (docs/SLAM.md, "Map segments") and frames before the map's first version: a
// camera that lost the map where relocalisation cannot succeed starts a segment of its own and
// joins it to the main map when it sees the main map again; a camera whose map is still being
// integrated is carried by the odometry. Lock-step mapping stepped by hand, so the numbers are
// the same run to run.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/slam/map_segment_poses.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "core/synthetic/synthetic_scene.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/core/slam/run_mapping_out.h"
#include "tests/core/slam/slam_test_options.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace map_segment_test {

constexpr double kPi = 3.14159265358979323846;
constexpr int kWidth = 160;
constexpr int kHeight = 120;

SlamOptions TestOptions() { return testing::SmallLockStepSlamOptions(); }

// A map that maps only when stepped (not in lock-step, which would map keyframe 0 before the
// camera's next frame) and one camera starting at the room's first true pose.
struct CameraBeforeMapping {
  CameraBeforeMapping(const InMemoryDataset& room, Backend* backend)
      : split(Concurrent()), map(split.mapper, split.gate),
        camera(StartingAt(split.tracker, *room.ground_truth(0)), backend) {}
  static SlamSplitOptions Concurrent() {
    SlamOptions o = TestOptions();
    o.deterministic = false;
    return SplitSlamOptions(o);
  }
  static SlamTrackerOptions StartingAt(SlamTrackerOptions o, const SE3& pose) {
    o.initial_pose = pose;
    return o;
  }
  const SlamSplitOptions split;
  SlamCoordinator map;
  SlamTracker camera;
};

// The synthetic circle's first camera turned in place by `yaw` (radians, about its own
// vertical axis), at frame `index`'s time (30 frames/s).
RgbdFrame TurnedView(double yaw, int index, const PinholeIntrinsics& k) {
  SyntheticOptions o;
  const SE3 start = SyntheticCameraPose(o, 0);
  const SE3 turn(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())),
                 Eigen::Vector3d::Zero());
  RgbdFrame frame = RenderSyntheticView(start * turn, k);
  frame.timestamp = index / 30.0;
  return frame;
}

// A covered lens: black, no depth.
RgbdFrame CoveredView(int index, const PinholeIntrinsics& k) {
  RgbdFrame frame = TurnedView(0.0, index, k);
  std::fill(frame.color.data.begin(), frame.color.data.end(), 0.0f);
  std::fill(frame.depth.data.begin(), frame.depth.data.end(), 0.0f);
  frame.ground_truth.reset();
  return frame;
}

double TranslationError(const SE3& a, const SE3& b) {
  return (a.translation() - b.translation()).norm();
}

double RotationErrorDegrees(const SE3& a, const SE3& b) {
  return Eigen::AngleAxisd(a.rotation().inverse() * b.rotation()).angle() * 180.0 / kPi;
}

TEST(SlamMapSegmentTest, PosesOfAJoinedSegmentMapIntoTheMainMap) {
  // Frames 0-1 in the main map, 2-3 in segment 1 (which joins at frame 4), 5-6 in segment 2
  // (started after another loss, never joined).
  const SE3 joined(Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(1.0, 0.0, 2.0));
  std::vector<SlamFrameResult> results(7);
  const int segments[] = {0, 0, 1, 1, 0, 2, 2};
  for (int i = 0; i < 7; ++i) {
    results[i].timestamp = i;
    results[i].segment = segments[i];
    results[i].pose = SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * i, 0.0, 0.0));
  }
  results[4].main_T_segment = joined;
  const std::map<int, SE3> joins = SegmentJoins(results);
  ASSERT_EQ(joins.size(), 1u);
  EXPECT_EQ(joins.count(1), 1u);
  const std::vector<StampedPose> poses = PosesInMainMap(results);
  ASSERT_EQ(poses.size(), 7u);
  for (int i = 0; i < 7; ++i) {
    const SE3 expected = segments[i] == 1 ? joined * results[i].pose : results[i].pose;
    EXPECT_EQ(poses[i].timestamp, i);
    EXPECT_LT(TranslationError(poses[i].pose, expected), 1e-12) << "frame " << i;
  }
  EXPECT_GT(TranslationError(poses[2].pose, results[2].pose), 0.5) << "segment 1 was moved";
}

TEST(SlamMapSegmentTest, AFrameBeforeTheFirstVersionIsCarriedByTheOdometry) {
  // Keyframe 0 is accepted but not integrated (the mapper has not stepped): frame 1 does not
  // wait for it; the odometry gives its pose, DEGRADED and never a keyframe.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(kWidth, kHeight, 4);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  CameraBeforeMapping setup(*room, backend.get());
  SlamCoordinator& map = setup.map;
  SlamTracker& camera = setup.camera;
  int segment = 0;
  for (int i = 0; i < 3; ++i) {
    const SlamMapView view = map.View(segment);
    ASSERT_EQ(view.map, nullptr);
    if (i > 0) {
      EXPECT_FALSE(camera.NeedsVersion(view)) << "frame " << i;
    }
    absl::StatusOr<SlamFrameResult> r = camera.Track(room->frames()[i], k, std::nullopt, view);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_TRUE(map.Accept(room->frames()[i], k, &*r, &segment).ok());
    if (i == 0) {
      EXPECT_TRUE(r->keyframe);
      continue;
    }
    EXPECT_EQ(r->state, SlamState::kDegraded) << r->reason;
    EXPECT_EQ(r->source, PoseSource::kOdometry);
    EXPECT_FALSE(r->keyframe);
    EXPECT_NE(r->reason.find("first version"), std::string::npos) << r->reason;
    // Noise-free frames ~1.5 cm apart: the odometry is within a few millimetres.
    EXPECT_LT(TranslationError(r->pose, *room->ground_truth(i)), 0.01) << "frame " << i;
  }
  // A second of the camera's own time is as far as the odometry carries it alone.
  RgbdFrame late = room->frames()[3];
  late.timestamp = 1.2;
  absl::StatusOr<SlamFrameResult> carried =
      camera.Track(late, k, std::nullopt, map.View(segment));
  ASSERT_TRUE(carried.ok()) << carried.status();
  EXPECT_EQ(carried->source, PoseSource::kOdometry);
  EXPECT_TRUE(camera.NeedsVersion(map.View(segment))) << "carried past a second";
  EXPECT_FALSE(camera.CarriesWithoutMap());
  EXPECT_EQ(map.progress().keyframes, 1);
  EXPECT_TRUE(map.MayCameraProceed(/*segment=*/0, /*needs_version=*/false));
  EXPECT_FALSE(map.MayCameraProceed(/*segment=*/0, /*needs_version=*/true));
}

TEST(SlamMapSegmentTest, TheNextKeyframeCarriesTheMotionTheMapDidNotConfirm) {
  // Frames 1-2 are carried by the odometry before the map's first version (DEGRADED); later
  // frames are tracked in the map. The camera's next keyframe says how far it moved on the
  // carried ones (loop closure's doubt in the edge into it); the one after that, nothing.
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(kWidth, kHeight, 24);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  CameraBeforeMapping setup(*room, backend.get());
  SlamCoordinator& map = setup.map;
  SlamTracker& camera = setup.camera;
  int segment = 0;
  std::vector<SlamFrameResult> keyframes;
  bool all_ok_after_carry = true;
  for (int i = 0; i < room->size(); ++i) {
    if (i == 3) {
      ASSERT_TRUE(map.StartMapper(backend.get()).ok());
      testing::RunMappingOut(map);
    }
    absl::StatusOr<SlamFrameResult> r =
        camera.Track(room->frames()[i], k, std::nullopt, map.View(segment));
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_TRUE(map.Accept(room->frames()[i], k, &*r, &segment).ok());
    if (i == 1 || i == 2) {
      ASSERT_EQ(r->source, PoseSource::kOdometry) << r->reason;
    } else if (i > 2 && keyframes.size() < 2) {
      all_ok_after_carry = all_ok_after_carry && r->state == SlamState::kOk;
    }
    if (r->keyframe) keyframes.push_back(*r);
    if (!r->keyframe) {
      EXPECT_EQ(r->unconfirmed.m, 0.0) << "frame " << i;
    }
    if (i >= 3 && r->keyframe) testing::RunMappingOut(map);
  }
  ASSERT_GE(keyframes.size(), 3u) << "the camera moved ~35 cm: keyframes every 10 cm";
  ASSERT_TRUE(all_ok_after_carry) << "the frames after the carried ones track OK";
  EXPECT_EQ(keyframes[0].unconfirmed.m, 0.0);
  // Frames 0 to 2 moved ~3 cm; the odometry is within a few millimetres of it.
  const SE3 start = *room->ground_truth(0), carried = *room->ground_truth(2);
  const double moved = (carried.translation() - start.translation()).norm();
  ASSERT_GT(moved, 0.01);
  EXPECT_NEAR(keyframes[1].unconfirmed.m, moved, 0.005);
  EXPECT_NEAR(keyframes[1].unconfirmed.rad, RotationAngleBetween(start, carried), 0.01);
  EXPECT_EQ(keyframes[2].unconfirmed.m, 0.0);
  EXPECT_EQ(keyframes[2].unconfirmed.rad, 0.0);
}

TEST(SlamMapSegmentTest, CoordinatorKeepsASegmentApartAndJoinsItByTheTransform) {
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(kWidth, kHeight, 8);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  const SlamSplitOptions split = SplitSlamOptions(TestOptions());
  int published = 0;
  SlamCoordinator map(split.mapper, split.gate, nullptr, 0,
                      [&](std::shared_ptr<const PlenoxelMap>, int) -> absl::StatusOr<int64_t> {
                        return ++published;
                      });
  ASSERT_TRUE(map.StartMapper(backend.get()).ok());
  int segment = 0;
  SlamFrameResult first;
  first.keyframe = true;
  first.pose = *room->ground_truth(0);
  ASSERT_TRUE(map.Accept(room->frames()[0], k, &first, &segment).ok());
  testing::RunMappingOut(map);
  const int main_versions = published;
  ASSERT_GE(main_versions, 1);

  // A camera starts segment 1; its frame of reference is off the main map's by `offset`.
  const SE3 offset(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(0.5, 0.0, -0.2));
  for (int i = 4; i < 7; ++i) {
    SlamFrameResult r;
    r.keyframe = true;
    r.new_segment = i == 4;
    r.pose = offset * *room->ground_truth(i);
    ASSERT_TRUE(map.Accept(room->frames()[i], k, &r, &segment).ok());
    EXPECT_EQ(segment, 1);
    EXPECT_EQ(r.segment, 1);
  }
  EXPECT_EQ(map.segments().started, 1);
  EXPECT_EQ(map.View(0).accepted_keyframes.size(), 1u) << "a segment's keyframes stay apart";
  SlamMapView view = map.View(1);
  EXPECT_EQ(view.segment, 1);
  EXPECT_EQ(view.map, nullptr);
  EXPECT_EQ(view.accepted_keyframes.size(), 3u);
  ASSERT_NE(view.main, nullptr);
  EXPECT_EQ(view.main->accepted_keyframes.size(), 1u);
  EXPECT_FALSE(map.MayCameraProceed(1, /*needs_version=*/true));
  testing::RunMappingOut(map);
  view = map.View(1);
  ASSERT_NE(view.map, nullptr) << "the segment's mapper integrated and published it";
  EXPECT_EQ(published, main_versions) << "only the main map reaches the publisher";
  EXPECT_EQ(map.progress().keyframes, 1);

  // The camera finds the main map: the segment's keyframes move into it at main_T_segment
  // times their poses (refined by the segment's mapper, so within millimetres).
  SlamFrameResult joining;
  joining.main_T_segment = offset.Inverse();
  joining.pose = *room->ground_truth(7);
  ASSERT_TRUE(map.Accept(room->frames()[7], k, &joining, &segment).ok());
  EXPECT_EQ(segment, 0);
  EXPECT_EQ(joining.segment, 0);
  EXPECT_EQ(map.segments().joined, 1);
  const SlamMapView main = map.View(0);
  ASSERT_EQ(main.accepted_keyframes.size(), 4u);
  for (int i = 1; i < 4; ++i) {
    EXPECT_LT(TranslationError(main.accepted_keyframes[i].pose, *room->ground_truth(i + 3)),
              0.01)
        << "keyframe " << i;
  }
  EXPECT_EQ(map.View(1).segment, 0) << "a joined segment's view is the main map's";
  EXPECT_FALSE(map.AddKeyframe(room->frames()[7], joining.pose, k, nullptr, 1).ok());
  testing::RunMappingOut(map);
  EXPECT_EQ(map.progress().keyframes_integrated, 4);
  EXPECT_GT(published, main_versions);
}

TEST(SlamMapSegmentTest, ALostCameraInUnseenSpaceStartsASegmentAndJoinsTheMapWhenItSeesItAgain) {
  // The camera maps straight ahead, its lens is covered while it turns 90 degrees in place,
  // and it is uncovered facing a part of the room the map never saw: relocalisation has
  // nothing to find, so after three such frames it starts a segment. It then turns back; once
  // its view overlaps the main map's again, its features find it there and the segment joins.
  const PinholeIntrinsics k = testing::SyntheticCamera(kWidth, kHeight);
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  SlamOptions options = TestOptions();
  const SlamSplitOptions split = SplitSlamOptions(options);
  SlamCoordinator map(split.mapper, split.gate);
  ASSERT_TRUE(map.StartMapper(backend.get()).ok());
  SlamTrackerOptions tracker_options = split.tracker;
  tracker_options.new_segment_after_lost_frames = 3;
  tracker_options.segment_join_interval = 2;
  tracker_options.initial_pose = *TurnedView(0.0, 0, k).ground_truth;
  SlamTracker camera(tracker_options, backend.get());

  int segment = 0;
  int index = 0;
  std::optional<int> started_at, joined_at;
  std::vector<std::pair<SE3, SE3>> after_join;  // (estimate, ground truth)
  auto process = [&](const RgbdFrame& frame) {
    absl::StatusOr<SlamFrameResult> r = camera.Track(frame, k, std::nullopt, map.View(segment));
    ASSERT_TRUE(r.ok()) << r.status();
    absl::StatusOr<bool> queued = map.Accept(frame, k, &*r, &segment);
    ASSERT_TRUE(queued.ok()) << queued.status();
    if (*queued) testing::RunMappingOut(map);
    if (r->new_segment) started_at = index;
    if (r->main_T_segment) joined_at = index;
    if (joined_at && frame.ground_truth) after_join.push_back({r->pose, *frame.ground_truth});
    ++index;
  };
  for (int i = 0; i < 8; ++i) process(TurnedView(0.0, index, k));
  ASSERT_EQ(segment, 0);
  for (int i = 0; i < 4; ++i) process(CoveredView(index, k));
  EXPECT_FALSE(started_at) << "a covered lens starts no segment";
  // Uncovered at 90 degrees, then turning back at 2 degrees a frame.
  const double away = 90.0 * kPi / 180.0;
  for (int i = 0; i < 4; ++i) process(TurnedView(away, index, k));
  ASSERT_TRUE(started_at) << "three LOST frames with depth start a segment";
  EXPECT_EQ(map.segments().started, 1);
  for (double yaw = away; yaw > -1e-9 && !joined_at; yaw -= 2.0 * kPi / 180.0) {
    process(TurnedView(yaw, index, k));
  }
  ASSERT_TRUE(joined_at) << "the segment never joined the main map";
  std::printf("segment started at frame %d, joined at frame %d\n", *started_at, *joined_at);
  EXPECT_EQ(segment, 0);
  EXPECT_EQ(map.segments().joined, 1);
  for (int i = 0; i < 10; ++i) process(TurnedView(0.0, index, k));
  ASSERT_FALSE(after_join.empty());
  for (const auto& [estimate, truth] : after_join) {
    EXPECT_LT(TranslationError(estimate, truth), 0.03);
    EXPECT_LT(RotationErrorDegrees(estimate, truth), 2.0);
  }
  // Every keyframe the segment took is in the main map now, near where it was.
  const SlamMapView main = map.View(0);
  EXPECT_GT(main.accepted_keyframes.size(), 1u);
  SyntheticOptions o;
  const SE3 start = SyntheticCameraPose(o, 0);
  for (const StampedPose& keyframe : main.keyframe_poses) {
    // Ground truth is a pure turn in place: the keyframe stays at the start's position.
    EXPECT_LT(TranslationError(keyframe.pose, start), 0.05)
        << "keyframe at " << keyframe.timestamp;
  }
  EXPECT_EQ(camera.counts().segments_started, 1);
  EXPECT_EQ(camera.counts().segments_joined, 1);
}

}  // namespace map_segment_test
}  // namespace plx

// A map pose the keyframes' features did not confirm, and the frames chained to it
// (core/slam/pose_fusion.h, ChainedToUnconfirmedPose): after a jump in the stream the map
// tracker can settle on a pose the features cannot back, and the frames after it track on from
// there (their odometry is relative to it, their map tracking starts there). None of them may
// be a keyframe until the features place one of them, and a chain they never place maps on in a
// segment of its own. Mapping is stepped by hand (lock-step), so the run is the same every time.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/cpu/cpu_backend.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "tests/core/slam/run_mapping_out.h"
#include "tests/core/slam/slam_test_options.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

constexpr int kWidth = 160;
constexpr int kHeight = 120;

// The room's camera in one map, mapping stepped after each keyframe.
class UnconfirmedChainTest : public ::testing::Test {
 protected:
  struct Tracked {
    SlamFrameResult result;
    double error_m = 0.0;  // from the truth, in the main map's frame when there
  };

  void Start(int new_segment_after_unconfirmed_frames) {
    room_ = testing::MakeSyntheticRoom(kWidth, kHeight, 90);
    ASSERT_NE(room_, nullptr);
    backend_ = MakeCpuBackend(1);
    SlamOptions o = testing::SmallLockStepSlamOptions();
    o.deterministic = false;  // mapping stepped here, after each keyframe
    o.initial_pose = *room_->ground_truth(0);
    o.new_segment_after_unconfirmed_frames = new_segment_after_unconfirmed_frames;
    const SlamSplitOptions split = SplitSlamOptions(o);
    map_ = std::make_unique<SlamCoordinator>(split.mapper, split.gate);
    camera_ = std::make_unique<SlamTracker>(split.tracker, backend_.get());
    ASSERT_TRUE(map_->StartMapper(backend_.get()).ok());
  }

  // Tracks the room's frame `source` at `timestamp`; with `blind_features` the keyframes'
  // features (the main map's too, seen from a segment) find nothing, so nothing can confirm a
  // map pose. With `label` it prints how the frame went.
  std::optional<Tracked> Track(int source, double timestamp, bool blind_features,
                               const char* label = nullptr) {
    RgbdFrame frame = room_->frames()[source];
    frame.timestamp = timestamp;
    SlamMapView view = map_->View(segment_);
    if (blind_features) {
      view.keyframe_features.clear();
      if (view.main != nullptr) {
        auto main = std::make_shared<SlamMapView>(*view.main);
        main->keyframe_features.clear();
        view.main = std::move(main);
      }
    }
    absl::StatusOr<SlamFrameResult> r = camera_->Track(frame, room_->calibration().pinhole,
                                                       std::nullopt, view);
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return std::nullopt;
    EXPECT_TRUE(map_->Accept(frame, room_->calibration().pinhole, &*r, &segment_).ok());
    if (r->keyframe) testing::RunMappingOut(*map_);
    const double error =
        (r->pose.translation() - room_->ground_truth(source)->translation()).norm();
    if (label != nullptr) {
      std::printf("%s, frame %d (segment %d): %s, %.1f cm off: %s\n", label, source,
                  r->segment, SlamStateName(r->state), 100 * error, r->reason.c_str());
    }
    return Tracked{std::move(*r), error};
  }

  static bool Chained(const SlamFrameResult& r) {
    return r.reason.find("follows from one") != std::string::npos;
  }

  std::unique_ptr<InMemoryDataset> room_;
  std::unique_ptr<Backend> backend_;
  std::unique_ptr<SlamCoordinator> map_;
  std::unique_ptr<SlamTracker> camera_;
  int segment_ = 0;
};

TEST_F(UnconfirmedChainTest, FramesChainedToAnUnconfirmedMapPoseAreNoKeyframesUntilConfirmed) {
  Start(/*new_segment_after_unconfirmed_frames=*/30);
  for (int i = 0; i < 60; ++i) ASSERT_TRUE(Track(i, i / 30.0, false));
  // A jump in the stream (the camera back where it was a second ago: the odometry refuses the
  // motion), with the keyframes' features blind. The map tracker settles ~60 cm off (measured)
  // on a view it explains, and the frames after it track on from there.
  int chained = 0;
  for (int source = 25; source < 35; ++source) {
    const std::optional<Tracked> t = Track(source, (source + 40) / 30.0, true, "blind features");
    ASSERT_TRUE(t);
    const SlamFrameResult* r = &t->result;
    EXPECT_EQ(r->state, SlamState::kDegraded) << "frame " << source << ": " << r->reason;
    EXPECT_FALSE(r->keyframe) << "frame " << source << ", " << 100 * t->error_m << " cm off";
    if (Chained(*r)) ++chained;
  }
  EXPECT_EQ(chained, 9) << "every frame after the jump's";
  // The features see again: they place the camera (the map's pose confirmed, or the camera
  // moved to where they and the map agree: here 60 cm, relocalised), and tracking is OK again.
  int placed_at = -1;
  for (int source = 35; source < 45; ++source) {
    const std::optional<Tracked> t = Track(source, (source + 40) / 30.0, false, "features back");
    ASSERT_TRUE(t);
    const SlamFrameResult* r = &t->result;
    if (placed_at < 0 && !Chained(*r)) placed_at = source;
    if (placed_at >= 0) {
      EXPECT_LT(t->error_m, 0.03) << "frame " << source;
      EXPECT_NE(r->state, SlamState::kDegraded) << "frame " << source << ": " << r->reason;
    } else {
      EXPECT_FALSE(r->keyframe) << "frame " << source;
    }
  }
  EXPECT_EQ(placed_at, 35) << "the first frame the features see places the camera";
}

TEST_F(UnconfirmedChainTest, AChainTheFeaturesNeverConfirmMapsOnInASegmentThatJoinsTheMap) {
  constexpr int kAfter = 8;
  Start(kAfter);
  for (int i = 0; i < 60; ++i) ASSERT_TRUE(Track(i, i / 30.0, false));
  // The same jump with the features blind for longer than the bound: the chain's first kAfter
  // frames map nothing, the last of them starts a segment (keyframe 0 there) where the chain
  // put the camera, and the camera maps on in it.
  int started_at = -1;
  int segment_keyframes = 0;
  for (int source = 25; source < 45; ++source) {
    const std::optional<Tracked> t = Track(source, (source + 40) / 30.0, true, "blind features");
    ASSERT_TRUE(t);
    const SlamFrameResult& r = t->result;
    if (r.new_segment) {
      EXPECT_EQ(started_at, -1) << "one segment";
      started_at = source;
      EXPECT_TRUE(r.keyframe);
      EXPECT_NE(r.reason.find("confirmed none of 8 frames"), std::string::npos) << r.reason;
    }
    if (started_at < 0) {
      EXPECT_FALSE(r.keyframe) << "frame " << source;
      EXPECT_EQ(r.state, SlamState::kDegraded) << "frame " << source << ": " << r.reason;
    } else {
      EXPECT_NE(r.segment, 0) << "frame " << source;
      EXPECT_NE(r.state, SlamState::kLost) << "frame " << source << ": " << r.reason;
      if (r.keyframe) ++segment_keyframes;
    }
  }
  EXPECT_EQ(started_at, 25 + kAfter - 1) << "the chain's 8th frame";
  EXPECT_GE(segment_keyframes, 2) << "the segment maps: keyframe 0 and the walk after it";
  // The features see again: the segment finds the main map, joins it, and the camera is back
  // in the main map's frame at its true place (the chain was ~60 cm off).
  int joined_at = -1;
  for (int source = 45; source < 70; ++source) {
    const std::optional<Tracked> t = Track(source, (source + 40) / 30.0, false, "features back");
    ASSERT_TRUE(t);
    if (t->result.main_T_segment) joined_at = source;
    if (joined_at >= 0) {
      EXPECT_EQ(t->result.segment, 0) << "frame " << source;
      EXPECT_LT(t->error_m, 0.03) << "frame " << source << ": " << t->result.reason;
    }
  }
  ASSERT_GE(joined_at, 45) << "the segment joins the main map";
  EXPECT_LT(joined_at, 45 + 2 * 5) << "within two of its attempts (segment_join_interval 5)";
  EXPECT_EQ(segment_, 0);
}

}  // namespace
}  // namespace plx

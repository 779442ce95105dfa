// A map pose the keyframes' features did not confirm, and the frames chained to it
// (core/slam/pose_fusion.h, ChainedToUnconfirmedPose): after a jump in the stream the map
// tracker can settle on a pose the features cannot back, and the frames after it track on from
// there (their odometry is relative to it, their map tracking starts there). None of them may
// be a keyframe until the features place one of them. Mapping is stepped by hand (lock-step),
// so the run is the same every time.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <optional>
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

TEST(UnconfirmedChainTest, FramesChainedToAnUnconfirmedMapPoseAreNoKeyframesUntilConfirmed) {
  std::unique_ptr<InMemoryDataset> room = testing::MakeSyntheticRoom(kWidth, kHeight, 90);
  ASSERT_NE(room, nullptr);
  const PinholeIntrinsics k = room->calibration().pinhole;
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  SlamOptions o = testing::SmallLockStepSlamOptions();
  o.deterministic = false;  // mapping stepped here, after each keyframe
  o.initial_pose = *room->ground_truth(0);
  const SlamSplitOptions split = SplitSlamOptions(o);
  SlamCoordinator map(split.mapper, split.gate);
  SlamTracker camera(split.tracker, backend.get());
  ASSERT_TRUE(map.StartMapper(backend.get()).ok());
  int segment = 0;
  // Tracks the room's frame `source` at `timestamp`; after the jump (`label` set) prints how it
  // went and how far from the truth it is.
  struct Tracked {
    SlamFrameResult result;
    double error_m = 0.0;
  };
  auto track = [&](int source, double timestamp, bool blind_features,
                   const char* label = nullptr) -> std::optional<Tracked> {
    RgbdFrame frame = room->frames()[source];
    frame.timestamp = timestamp;
    SlamMapView view = map.View(segment);
    // The keyframes' features find nothing: nothing can confirm a map pose.
    if (blind_features) view.keyframe_features.clear();
    absl::StatusOr<SlamFrameResult> r = camera.Track(frame, k, std::nullopt, view);
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return std::nullopt;
    EXPECT_TRUE(map.Accept(frame, k, &*r, &segment).ok());
    if (r->keyframe) testing::RunMappingOut(map);
    const double error =
        (r->pose.translation() - room->ground_truth(source)->translation()).norm();
    if (label != nullptr) {
      std::printf("%s, frame %d: %s, %.1f cm off: %s\n", label, source, SlamStateName(r->state),
                  100 * error, r->reason.c_str());
    }
    return Tracked{std::move(*r), error};
  };
  for (int i = 0; i < 60; ++i) ASSERT_TRUE(track(i, i / 30.0, false));
  // A jump in the stream (the camera back where it was a second ago: the odometry refuses the
  // motion), with the keyframes' features blind. The map tracker settles ~60 cm off (measured)
  // on a view it explains, and the frames after it track on from there.
  int chained = 0;
  for (int source = 25; source < 35; ++source) {
    const std::optional<Tracked> t = track(source, (source + 40) / 30.0, true, "blind features");
    ASSERT_TRUE(t);
    const SlamFrameResult* r = &t->result;
    const double error = t->error_m;
    EXPECT_EQ(r->state, SlamState::kDegraded) << "frame " << source << ": " << r->reason;
    EXPECT_FALSE(r->keyframe) << "frame " << source << ", " << 100 * error << " cm off";
    if (r->reason.find("follows from one") != std::string::npos) ++chained;
  }
  EXPECT_EQ(chained, 9) << "every frame after the jump's";
  // The features see again: they place the camera (the map's pose confirmed, or the camera
  // moved to where they and the map agree: here 60 cm, relocalised), and tracking is OK again.
  int placed_at = -1;
  for (int source = 35; source < 45; ++source) {
    const std::optional<Tracked> t = track(source, (source + 40) / 30.0, false, "features back");
    ASSERT_TRUE(t);
    const SlamFrameResult* r = &t->result;
    const double error = t->error_m;
    if (placed_at < 0 && r->reason.find("follows from one") == std::string::npos) {
      placed_at = source;
    }
    if (placed_at >= 0) {
      EXPECT_LT(error, 0.03) << "frame " << source;
      EXPECT_NE(r->state, SlamState::kDegraded) << "frame " << source << ": " << r->reason;
    } else {
      EXPECT_FALSE(r->keyframe) << "frame " << source;
    }
  }
  EXPECT_EQ(placed_at, 35) << "the first frame the features see places the camera";
}

}  // namespace
}  // namespace plx

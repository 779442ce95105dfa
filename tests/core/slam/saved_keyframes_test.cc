// SLAM continuing a saved map (issue 24, part 2): one session maps the first part of the room,
// its map and keyframes go through a map file, and a second coordinator seeded with the saved
// keyframes (SlamCoordinator::SeedSavedKeyframes) lets a new camera find itself by their
// features, counts its keyframes on from them, and publishes them with its own. Lock-step
// mapping, so the numbers are the same run to run.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/formats/map_file.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "gmock/gmock.h"
#include "tests/core/slam/run_mapping_out.h"
#include "tests/core/slam/slam_test_options.h"
#include "tests/synthetic_room.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

constexpr int kFirstRun = 30;  // frames the first session maps
// Where the second camera starts: in the saved map, a few frames before where the first
// session stopped (a client coming back after a restart), then on into new ground. The
// synthetic room's features place a frame within a centimetre or two near a keyframe; a few
// frames further on PnP is decimetres off and the dense check rightly refuses it.
constexpr int kSecondStart = 24;
constexpr int kFrames = 45;

// One frame, as the daemon's stream does it: tracked in the view, its keyframe handed over and
// (lock-step) mapped before the next frame.
SlamFrameResult Process(SlamTracker& tracker, SlamCoordinator& coordinator,
                        const RgbdFrame& frame, const PinholeIntrinsics& k) {
  absl::StatusOr<SlamFrameResult> r = tracker.Track(frame, k, std::nullopt, coordinator.View());
  EXPECT_TRUE(r.ok()) << r.status();
  if (!r.ok()) return SlamFrameResult();
  if (r->keyframe) {
    int segment = 0;
    EXPECT_TRUE(coordinator.Accept(frame, k, &*r, &segment).ok());
    testing::RunMappingOut(coordinator);
  }
  return *r;
}

class SavedKeyframesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    room_ = testing::MakeSyntheticRoom(160, 120, kFrames).release();
    ASSERT_NE(room_, nullptr);
    dir_ = new std::string(plx::testing::MakeTempDir("saved_keyframes_test"));
    // The first session: frames 0 .. kFirstRun-1 from frame 0's true pose, its versions
    // numbered by a publisher as the daemon's store numbers them.
    const SlamSplitOptions split = SplitSlamOptions(Options());
    int64_t next_version = 1;
    SlamCoordinator first(split.mapper, split.gate, nullptr, 0,
                          [&](std::shared_ptr<const PlenoxelMap>, int) -> absl::StatusOr<int64_t> {
                            return next_version++;
                          });
    std::unique_ptr<Backend> backend = MakeCpuBackend(1);
    ASSERT_TRUE(first.StartMapper(backend.get()).ok());
    SlamTrackerOptions o = split.tracker;
    o.initial_pose = *room_->ground_truth(0);
    SlamTracker camera(o, backend.get());
    const PinholeIntrinsics& k = room_->calibration().pinhole;
    for (int i = 0; i < kFirstRun; ++i) {
      const SlamFrameResult r = Process(camera, first, room_->frames()[i], k);
      ASSERT_NE(r.state, SlamState::kLost) << "frame " << i;
    }
    saved_ = new MapKeyframes(*first.published_keyframes());
    first_version_ = first.latest().version;
    MapFileState state;
    state.map_version = static_cast<uint64_t>(first_version_);
    state.keyframes = *saved_;
    ASSERT_TRUE(SaveMap(*first.latest().map, state, File()).ok());
  }
  static void TearDownTestSuite() {
    delete room_;
    delete saved_;
    delete dir_;
  }

  static SlamOptions Options() { return testing::SmallLockStepSlamOptions(); }
  static std::string File() { return *dir_ + "/room.plx"; }

  // A coordinator continuing the saved map, its mapper started; seeded with the file's
  // keyframes when `seed`.
  std::unique_ptr<SlamCoordinator> Continue(bool seed) {
    absl::StatusOr<LoadedMapFile> loaded = LoadMapFile(File());
    EXPECT_TRUE(loaded.ok()) << loaded.status();
    if (!loaded.ok()) return nullptr;
    EXPECT_EQ(loaded->state.map_version, static_cast<uint64_t>(first_version_));
    const SlamSplitOptions split = SplitSlamOptions(Options());
    // Numbered on from the saved version, as the daemon's store numbers them.
    auto c = std::make_unique<SlamCoordinator>(
        split.mapper, split.gate, std::shared_ptr<const PlenoxelMap>(std::move(loaded->map)),
        first_version_,
        [next = first_version_](std::shared_ptr<const PlenoxelMap>,
                                int) mutable -> absl::StatusOr<int64_t> { return ++next; });
    if (seed) {
      const absl::Status seeded = c->SeedSavedKeyframes(loaded->state.keyframes);
      EXPECT_TRUE(seeded.ok()) << seeded;
    }
    EXPECT_TRUE(c->StartMapper(backend_.get()).ok());
    return c;
  }
  // A camera that knows nowhere to start (no initial pose: the identity), as a client
  // reconnecting after a restart.
  std::unique_ptr<SlamTracker> Camera() {
    return std::make_unique<SlamTracker>(SplitSlamOptions(Options()).tracker, backend_.get());
  }

  static inline InMemoryDataset* room_ = nullptr;
  static inline std::string* dir_ = nullptr;
  static inline MapKeyframes* saved_ = nullptr;
  static inline int64_t first_version_ = 0;
  std::unique_ptr<Backend> backend_ = MakeCpuBackend(1);
};

TEST_F(SavedKeyframesTest, TheFileKeepsEveryKeyframeWithItsFeatures) {
  ASSERT_GE(saved_->size(), 3u);
  absl::StatusOr<LoadedMapFile> loaded = LoadMapFile(File());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_EQ(loaded->state.keyframes.size(), saved_->size());
  for (size_t i = 0; i < saved_->size(); ++i) {
    const MapKeyframe& a = (*saved_)[i];
    const MapKeyframe& b = loaded->state.keyframes[i];
    EXPECT_EQ(a.timestamp, b.timestamp);
    EXPECT_LT((a.pose.translation() - b.pose.translation()).norm(), 1e-12);
    EXPECT_EQ(a.intrinsics, b.intrinsics);
    ASSERT_NE(a.features, nullptr) << "keyframe " << i;
    ASSERT_NE(b.features, nullptr) << "keyframe " << i;
    EXPECT_GT(b.features->size(), 20) << "keyframe " << i;
    EXPECT_EQ(a.features->descriptors, b.features->descriptors);
    EXPECT_EQ(a.features->thumbnail, b.features->thumbnail);
  }
}

TEST_F(SavedKeyframesTest, ASeededMapListsAndCountsTheSavedKeyframesFirst) {
  const std::unique_ptr<SlamCoordinator> c = Continue(/*seed=*/true);
  ASSERT_NE(c, nullptr);
  const int saved = static_cast<int>(saved_->size());
  const SlamMapView view = c->View();
  EXPECT_EQ(view.version, first_version_);
  ASSERT_EQ(static_cast<int>(view.accepted_keyframes.size()), saved);
  ASSERT_EQ(static_cast<int>(view.keyframe_poses.size()), saved);
  ASSERT_EQ(static_cast<int>(view.keyframe_features.size()), saved);
  for (int i = 0; i < saved; ++i) {
    ASSERT_NE(view.keyframe_features[i], nullptr) << "keyframe " << i;
    EXPECT_EQ(view.keyframe_features[i]->descriptors, (*saved_)[i].features->descriptors);
    EXPECT_EQ(view.keyframe_poses[i].timestamp, (*saved_)[i].timestamp);
    EXPECT_EQ(view.accepted_keyframes[i].timestamp, (*saved_)[i].timestamp);
  }
  const SlamMapperProgress p = c->progress();
  EXPECT_EQ(p.keyframes, saved);
  EXPECT_EQ(p.keyframes_integrated, saved);
  EXPECT_EQ(p.pending_keyframes, 0);
  EXPECT_EQ(static_cast<int>(c->keyframe_poses().size()), saved);
  EXPECT_EQ(static_cast<int>(c->published_keyframes()->size()), saved);
  // Once, before the mapper: a second seed is refused.
  EXPECT_EQ(c->SeedSavedKeyframes(*saved_).code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(SavedKeyframesTest, SeedingNeedsABaseMapAndComesBeforeTheMapper) {
  const SlamSplitOptions split = SplitSlamOptions(Options());
  SlamCoordinator no_base(split.mapper, split.gate);
  EXPECT_EQ(no_base.SeedSavedKeyframes(*saved_).code(), absl::StatusCode::kFailedPrecondition);
  const std::unique_ptr<SlamCoordinator> started = Continue(/*seed=*/false);
  ASSERT_NE(started, nullptr);
  EXPECT_EQ(started->SeedSavedKeyframes(*saved_).code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(SavedKeyframesTest, ANewCameraRelocalisesByTheSavedFeaturesAndCountsOn) {
  const std::unique_ptr<SlamCoordinator> c = Continue(/*seed=*/true);
  ASSERT_NE(c, nullptr);
  const std::unique_ptr<SlamTracker> camera = Camera();
  const PinholeIntrinsics& k = room_->calibration().pinhole;
  const int saved = static_cast<int>(saved_->size());
  int keyframes = 0;
  double worst_m = 0.0;
  for (int i = kSecondStart; i < kFrames; ++i) {
    const SlamFrameResult r = Process(*camera, *c, room_->frames()[i], k);
    if (i == kSecondStart) {
      // Far from the identity it starts at: only the saved keyframes' features can place it.
      EXPECT_EQ(r.state, SlamState::kRelocalised) << r.reason;
      EXPECT_THAT(r.reason, HasSubstr("features"));
    } else {
      EXPECT_NE(r.state, SlamState::kLost) << "frame " << i << ": " << r.reason;
    }
    EXPECT_GE(r.keyframes, saved) << "frame " << i;
    keyframes += r.keyframe;
    if (r.state != SlamState::kLost) {
      worst_m = std::max(
          worst_m, (r.pose.translation() - room_->ground_truth(i)->translation()).norm());
    }
  }
  std::printf("continued from %d saved keyframes: %d new, worst position error %.1f mm\n",
              saved, keyframes, 1000 * worst_m);
  // In the saved map's frame (the first session started at the true pose), to the centimetre.
  EXPECT_LT(worst_m, 0.03);
  ASSERT_GT(keyframes, 0) << "the second half of the path is new ground";
  const SlamMapperProgress p = c->progress();
  EXPECT_EQ(p.keyframes, saved + keyframes);
  EXPECT_EQ(p.keyframes_integrated, saved + keyframes);
  // What the next save writes: the saved keyframes as they were, then the new ones with
  // their features.
  const std::shared_ptr<const MapKeyframes> published = c->published_keyframes();
  ASSERT_EQ(static_cast<int>(published->size()), saved + keyframes);
  for (int i = 0; i < saved; ++i) {
    ASSERT_NE((*published)[i].features, nullptr) << "keyframe " << i;
    EXPECT_EQ((*published)[i].features->descriptors, (*saved_)[i].features->descriptors);
    EXPECT_EQ((*published)[i].timestamp, (*saved_)[i].timestamp);
  }
  for (int i = saved; i < saved + keyframes; ++i) {
    EXPECT_NE((*published)[i].features, nullptr) << "keyframe " << i;
    EXPECT_GE((*published)[i].timestamp, room_->timestamp(kSecondStart));
  }
  EXPECT_GT(c->latest().version, first_version_);
}

// The control: the same camera on the same map without its keyframes has nothing to find
// itself by, and counts from zero (what a reloaded map did before map files kept keyframes).
TEST_F(SavedKeyframesTest, WithoutTheSavedKeyframesTheCameraCannotPlaceItself) {
  const std::unique_ptr<SlamCoordinator> c = Continue(/*seed=*/false);
  ASSERT_NE(c, nullptr);
  const std::unique_ptr<SlamTracker> camera = Camera();
  const SlamFrameResult r =
      Process(*camera, *c, room_->frames()[kSecondStart], room_->calibration().pinhole);
  EXPECT_THAT(r.reason, Not(HasSubstr("features")));
  EXPECT_NE(r.state, SlamState::kRelocalised) << r.reason;
  EXPECT_LE(r.keyframes, 1);
}

}  // namespace
}  // namespace plx

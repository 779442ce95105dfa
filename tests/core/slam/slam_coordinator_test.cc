// SlamCoordinator's rules on their own, driven by hand as a caller would: the options split,
// keyframes before the mapper, the gate, the step modes (drain) and the view's numbering.
#include "core/slam/slam_coordinator.h"

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/slam/slam_session.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

SlamOptions SmallOptions(bool deterministic) {
  SlamOptions o = DefaultSlamOptions();
  o.deterministic = deterministic;
  o.tracker.rays = 512;
  o.mapping.mapper = MapperOptionsForVoxelSize(0.02f);
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.batch_size = 1024;
  o.mapping.iterations_per_keyframe = 10;
  o.refinement.window = 0;
  return o;
}

class SlamCoordinatorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    room_ = testing::MakeSyntheticRoom(80, 60, 20);
    ASSERT_NE(room_, nullptr);
    backend_ = MakeCpuBackend(1);
  }
  RgbdFrame Frame(int i) {
    absl::StatusOr<RgbdFrame> f = room_->LoadFrame(i);
    EXPECT_TRUE(f.ok()) << f.status();
    return f.ok() ? *std::move(f) : RgbdFrame();
  }
  SE3 Pose(int i) { return *room_->ground_truth(i); }
  const PinholeIntrinsics& K() { return room_->calibration().pinhole; }
  void AddKeyframe(SlamCoordinator& c, int i) {
    ASSERT_TRUE(c.AddKeyframe(Frame(i), Pose(i), K()).ok());
  }
  // Steps in `mode` until the coordinator is out of work; returns the steps taken.
  int RunOut(SlamCoordinator& c, SlamStepMode mode) {
    for (int steps = 1; steps < 1000; ++steps) {
      absl::StatusOr<SlamStepResult> r = c.Step(mode);
      EXPECT_TRUE(r.ok()) << r.status();
      if (!r.ok() || r->out_of_work) return steps;
    }
    ADD_FAILURE() << "never out of work";
    return 0;
  }

  std::unique_ptr<InMemoryDataset> room_;
  std::unique_ptr<Backend> backend_;
};

TEST_F(SlamCoordinatorTest, SplitAppliesTheLockStepPolicyOnlyWhenDeterministic) {
  SlamOptions o = SmallOptions(false);
  o.max_pending_keyframes = 2;
  o.mapping.min_publish_interval_s = 0.5;
  o.mapping.max_clones_per_iteration = 7;
  const SlamSplitOptions free = SplitSlamOptions(o);
  EXPECT_EQ(free.mapper.mapping.min_publish_interval_s, 0.5);
  EXPECT_EQ(free.mapper.mapping.max_clones_per_iteration, 7);
  EXPECT_FALSE(free.gate.lock_step);
  EXPECT_EQ(free.gate.max_pending_keyframes, 2);
  EXPECT_EQ(free.tracker.max_pending_keyframes, 2);  // the tracker defers beyond the same bound
  EXPECT_EQ(free.tracker.tracker.rays, 512);
  EXPECT_EQ(free.tracker.map_time_budget, o.map_time_budget);

  // Lock-step leaves nothing pending: the bound (here not the default) is ignored, not refused.
  o.deterministic = true;
  EXPECT_TRUE(ValidateSlamOptions(o).ok());
  const SlamSplitOptions locked = SplitSlamOptions(o);
  EXPECT_EQ(locked.gate.max_pending_keyframes, 0);
  EXPECT_EQ(locked.tracker.max_pending_keyframes, 0);
  EXPECT_EQ(locked.tracker.map_time_budget, 0.0);  // a time bound would depend on the machine
  SlamMapperOptions expected = free.mapper;
  ApplyLockStepMappingPolicy(&expected);
  EXPECT_EQ(locked.mapper.mapping.min_publish_interval_s,
            expected.mapping.min_publish_interval_s);
  EXPECT_EQ(locked.mapper.mapping.max_clones_per_iteration, 0);
  // Wall time bounds neither a chunk nor a solve (concurrently it bounds both).
  EXPECT_EQ(locked.mapper.mapping.chunk_seconds, kLockStepUnreachedSeconds);
  EXPECT_EQ(locked.mapper.loop_closure.graph.max_solve_seconds, kLockStepUnreachedSeconds);
  EXPECT_LT(free.mapper.mapping.chunk_seconds, 1.0);
  EXPECT_LT(free.mapper.loop_closure.graph.max_solve_seconds, 1.0);
  EXPECT_TRUE(locked.gate.lock_step);

  // A budget under the median would cut most frames, not the costly ones.
  o.deterministic = false;
  o.map_time_budget = 0.5;
  EXPECT_FALSE(ValidateSlamOptions(o).ok());
}

TEST_F(SlamCoordinatorTest, KeyframesBeforeTheMapperAreSeenAndHandedOver) {
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(true));
  SlamCoordinator c(split.mapper, split.gate);
  EXPECT_FALSE(c.mapper_started());
  AddKeyframe(c, 0);
  SlamMapView view = c.View();
  EXPECT_EQ(view.map, nullptr);
  EXPECT_EQ(view.version, 0);
  ASSERT_EQ(view.accepted_keyframes.size(), 1u);
  EXPECT_TRUE(view.mapping_behind());
  EXPECT_FALSE(c.MayCameraProceed());  // no version yet
  EXPECT_EQ(c.progress().pending_keyframes, 1);
  EXPECT_FALSE(c.Step(SlamStepMode::kMap).ok());  // StartMapper first

  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  EXPECT_TRUE(c.mapper_started());
  RunOut(c, SlamStepMode::kMap);
  view = c.View();
  ASSERT_NE(view.map, nullptr);
  EXPECT_GE(view.version, 1);
  EXPECT_EQ(view.accepted_keyframes.size(), 1u);
  EXPECT_EQ(view.keyframe_poses.size(), 1u);
  EXPECT_FALSE(view.mapping_behind());
  const SlamMapperProgress p = c.progress();
  EXPECT_EQ(p.keyframes, 1);
  EXPECT_EQ(p.keyframes_integrated, 1);
  EXPECT_EQ(p.map_version, view.version);
  EXPECT_TRUE(p.idle);
  EXPECT_TRUE(c.MayCameraProceed());
}

TEST_F(SlamCoordinatorTest, LockStepGateWaitsUntilMappingIsIdle) {
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(true));
  SlamCoordinator c(split.mapper, split.gate);
  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  AddKeyframe(c, 0);
  RunOut(c, SlamStepMode::kMap);
  ASSERT_TRUE(c.MayCameraProceed());
  const int64_t version = c.View().version;
  AddKeyframe(c, 5);
  EXPECT_FALSE(c.MayCameraProceed());
  // Integrated but the iterations not spent: still waiting in lock-step.
  for (int i = 0; i < 1000 && c.progress().pending_keyframes > 0; ++i) {
    ASSERT_TRUE(c.Step(SlamStepMode::kMap).ok());
  }
  ASSERT_EQ(c.progress().pending_keyframes, 0);
  EXPECT_FALSE(c.progress().idle);
  EXPECT_FALSE(c.MayCameraProceed());
  RunOut(c, SlamStepMode::kMap);
  EXPECT_TRUE(c.MayCameraProceed());
  EXPECT_GT(c.View().version, version);
}

TEST_F(SlamCoordinatorTest, ConcurrentGateLetsACameraRunAheadByMaxPendingKeyframes) {
  SlamOptions o = SmallOptions(false);
  o.max_pending_keyframes = 1;
  const SlamSplitOptions split = SplitSlamOptions(o);
  SlamCoordinator c(split.mapper, split.gate);
  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  AddKeyframe(c, 0);
  EXPECT_FALSE(c.MayCameraProceed());  // one pending is allowed, but there is no version
  RunOut(c, SlamStepMode::kMap);
  AddKeyframe(c, 5);
  EXPECT_TRUE(c.MayCameraProceed());   // one pending, a version out
  AddKeyframe(c, 10);
  EXPECT_FALSE(c.MayCameraProceed());  // two pending
  for (int i = 0; i < 1000 && c.progress().pending_keyframes > 1; ++i) {
    ASSERT_TRUE(c.Step(SlamStepMode::kMap).ok());
  }
  EXPECT_TRUE(c.MayCameraProceed());  // not idle: only lock-step waits for that
}

TEST_F(SlamCoordinatorTest, DrainIntegratesTheAcceptedKeyframesThenPublishesAndStops) {
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(true));
  SlamCoordinator c(split.mapper, split.gate);
  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  AddKeyframe(c, 0);
  RunOut(c, SlamStepMode::kMap);
  const int iterations_mapped = c.progress().mapping_iterations;
  const int64_t version = c.View().version;
  AddKeyframe(c, 5);
  AddKeyframe(c, 10);
  RunOut(c, SlamStepMode::kDrain);
  const SlamMapperProgress p = c.progress();
  EXPECT_EQ(p.pending_keyframes, 0);
  EXPECT_EQ(p.keyframes_integrated, 3);
  // The two keyframes' iteration budget is not spent, and the map with them is out.
  EXPECT_LT(p.mapping_iterations - iterations_mapped, 2 * 10);
  EXPECT_FALSE(p.idle);
  EXPECT_GT(c.View().version, version);
  EXPECT_EQ(c.View().version, p.map_version);
  // Out of work for the drain: a further step does nothing.
  absl::StatusOr<SlamStepResult> again = c.Step(SlamStepMode::kDrain);
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(again->stepped);
  EXPECT_FALSE(again->published);
  EXPECT_TRUE(again->out_of_work);
}

TEST_F(SlamCoordinatorTest, ThePublisherNumbersTheVersionsTheViewShows) {
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(true));
  std::vector<int> new_keyframes;
  int64_t next = 40;
  SlamCoordinator c(split.mapper, split.gate, nullptr, 39,
                    [&](std::shared_ptr<const PlenoxelMap> map,
                        int keyframes) -> absl::StatusOr<int64_t> {
                      EXPECT_NE(map, nullptr);
                      new_keyframes.push_back(keyframes);
                      return next++;
                    });
  EXPECT_EQ(c.View().version, 0);      // no map: no version to track against
  EXPECT_EQ(c.progress().map_version, 39);  // the map's number all the same
  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  AddKeyframe(c, 0);
  RunOut(c, SlamStepMode::kMap);
  EXPECT_GE(next, 41);
  EXPECT_EQ(c.View().version, next - 1);  // the last number handed out
  AddKeyframe(c, 5);
  RunOut(c, SlamStepMode::kFinish);
  EXPECT_EQ(c.View().version, next - 1);
  EXPECT_EQ(c.latest().version, next - 1);
  EXPECT_EQ(c.progress().map_version, next - 1);
  // Each keyframe counted once, with the first version that has it.
  ASSERT_FALSE(new_keyframes.empty());
  EXPECT_EQ(new_keyframes.front(), 1);
  int total = 0;
  for (int n : new_keyframes) total += n;
  EXPECT_EQ(total, 2);
}

TEST_F(SlamCoordinatorTest, EachCamerasKeyframesChainToItsOwnInLoopClosuresGraph) {
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(false));
  SlamCoordinator c(split.mapper, split.gate);
  int segment_a = 0, segment_b = 0, segment_unknown = 0;
  int frame = 0;
  // A keyframe of `camera` (-1: a caller that does not say); `change` sets up a segment start
  // or a join on the result.
  auto keyframe = [&](int camera, int* segment, double unconfirmed_m = 0.0,
                      const std::function<void(SlamFrameResult*)>& change = nullptr) {
    SlamFrameResult r;
    r.keyframe = true;
    r.pose = Pose(frame);
    r.unconfirmed.m = unconfirmed_m;
    if (change) change(&r);
    ASSERT_TRUE(c.Accept(Frame(frame), K(), &r, segment, camera).ok());
    ++frame;
  };
  keyframe(0, &segment_a);                   // main 0: the first
  keyframe(1, &segment_b);                   // main 1: B's first, from the one before
  keyframe(0, &segment_a);                   // main 2: from A's 0
  keyframe(1, &segment_b, 0.25);             // main 3: from B's 1, with B's doubt
  keyframe(-1, &segment_unknown);            // main 4: no camera, from the one before
  keyframe(0, &segment_a, 0.0, [](SlamFrameResult* r) { r->new_segment = true; });
  ASSERT_EQ(segment_a, 1);                   // A lost the map: its segment's 0
  keyframe(0, &segment_a);                   // the segment's 1
  keyframe(1, &segment_b);                   // main 5: from B's 3
  keyframe(0, &segment_a, 0.0, [](SlamFrameResult* r) { r->main_T_segment = SE3::Identity(); });
  ASSERT_EQ(segment_a, 0);
  // The join moved A's segment in (main 6 and 7), then A's joining keyframe (main 8): A's
  // chain starts again at the join, tied to the keyframe before it, not to A's main 2.
  const std::vector<SequentialLink> links = c.sequential_links();
  const std::vector<int> expected_from = {-1, -1, 0, 1, -1, 3, -1, 6, 7};
  ASSERT_EQ(links.size(), expected_from.size());
  for (size_t i = 0; i < links.size(); ++i) {
    EXPECT_EQ(links[i].from, expected_from[i]) << "keyframe " << i;
  }
  EXPECT_EQ(links[3].unconfirmed.m, 0.25);
  EXPECT_EQ(links[5].unconfirmed.m, 0.0);
}

TEST_F(SlamCoordinatorTest, ANewSegmentGetsAVersionWhileTheMainMapStillHasWork) {
  // A camera that lost the main map starts a segment and needs a version of it to track; the
  // main map, busy with its iterations, must not hold that back until it runs out of work.
  const SlamSplitOptions split = SplitSlamOptions(SmallOptions(false));
  SlamCoordinator c(split.mapper, split.gate);
  ASSERT_TRUE(c.StartMapper(backend_.get()).ok());
  for (int i = 0; i < 3; ++i) AddKeyframe(c, i);
  // The main map's keyframes are in; their iterations remain (30).
  for (int i = 0; i < 200 && c.progress().pending_keyframes > 0; ++i) {
    ASSERT_TRUE(c.Step(SlamStepMode::kMap).ok());
  }
  ASSERT_EQ(c.progress().pending_keyframes, 0);
  ASSERT_FALSE(c.progress().idle);
  SlamFrameResult lost;
  lost.keyframe = true;
  lost.new_segment = true;
  lost.pose = Pose(10);
  int segment = 0;
  ASSERT_TRUE(c.Accept(Frame(10), K(), &lost, &segment, /*camera=*/0).ok());
  ASSERT_EQ(segment, 1);
  int steps = 0;
  while (c.View(segment).map == nullptr && steps < 200) {
    absl::StatusOr<SlamStepResult> r = c.Step(SlamStepMode::kMap);
    ASSERT_TRUE(r.ok()) << r.status();
    ++steps;
  }
  ASSERT_NE(c.View(segment).map, nullptr);
  EXPECT_FALSE(c.progress().idle) << "the main map ran out of work first (" << steps
                                  << " steps)";
  EXPECT_TRUE(c.MayCameraProceed(segment, /*needs_version=*/true));
  // The segment's next keyframe reaches its camera as soon as it is in, too.
  const std::shared_ptr<const PlenoxelMap> first = c.View(segment).map;
  SlamFrameResult next;
  next.keyframe = true;
  next.pose = Pose(12);
  ASSERT_TRUE(c.Accept(Frame(12), K(), &next, &segment, /*camera=*/0).ok());
  for (steps = 0; c.View(segment).map == first && steps < 200; ++steps) {
    ASSERT_TRUE(c.Step(SlamStepMode::kMap).ok());
  }
  EXPECT_NE(c.View(segment).map, first);
  EXPECT_FALSE(c.progress().idle) << "the main map ran out of work first (" << steps
                                  << " steps)";
}

}  // namespace
}  // namespace plx

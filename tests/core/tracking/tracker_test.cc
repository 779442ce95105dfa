#include "core/tracking/tracker.h"

#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "core/mapping/map_dataset.h"
#include "core/synthetic/synthetic_sequence.h"
#include "core/tracking/track_dataset.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

// One noise-free synthetic sequence and a 2 cm map of its keyframes 0, 10, 20, shared by the
// tests (mapping is the slow part).
class TrackerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dataset_ = testing::MakeSyntheticRoom(160, 120, 30).release();
    ASSERT_NE(dataset_, nullptr);
    backend_ = MakeCpuBackend(2).release();
    MapperOptions m = MapperOptionsForVoxelSize(0.02f);
    m.max_iterations = 200;
    auto mapped = MapDataset(*dataset_, KeyframeIndices(30, 10), m, *backend_);
    ASSERT_TRUE(mapped.ok()) << mapped.status();
    map_ = mapped->map.release();
  }
  static void TearDownTestSuite() {
    delete map_;
    delete backend_;
    delete dataset_;
  }

  static TrackingResult TrackFrom(const SE3& start, int frame, const TrackerOptions& options) {
    Tracker tracker(map_, backend_, options);
    const RgbdFrame& f = dataset_->frames()[frame];
    tracker.Reset(start, f.timestamp - 1.0 / 30);
    return tracker.Track(f, dataset_->calibration().pinhole, start).value();
  }

  // Frame `frame`'s true pose moved 5.4 cm and 3.1 degrees.
  static SE3 PerturbedPose(int frame) {
    Vector6d offset;
    offset << 0.03, -0.04, 0.02, 0.03, -0.02, 0.04;
    return *dataset_->frames()[frame].ground_truth * SE3::Exp(offset);
  }

  static InMemoryDataset* dataset_;
  static Backend* backend_;
  static PlenoxelMap* map_;
};
InMemoryDataset* TrackerTest::dataset_ = nullptr;
Backend* TrackerTest::backend_ = nullptr;
PlenoxelMap* TrackerTest::map_ = nullptr;

// 5.4 cm and 3.1 degrees off: recovered to well under a millimetre and 0.1 degree (measured
// 0.93 mm / 0.014 deg on the keyframe with the default 2048 chosen rays). So far out, 12
// iterations were not always enough (one draw of 2048 chosen rays stopped at 16 mm; 1024 and
// 4096, chosen or uniform, reached 0.4-0.8 mm): 16 leave the schedule room.
TEST_F(TrackerTest, RecoversAPerturbedPose) {
  const SE3 truth = *dataset_->frames()[10].ground_truth;
  TrackerOptions options;
  options.iterations = 16;
  const TrackingResult r = TrackFrom(PerturbedPose(10), 10, options);
  EXPECT_EQ(r.state, TrackingState::kOk) << r.reason;
  const SE3 error = truth.Inverse() * r.pose;
  EXPECT_LT(error.translation().norm(), 1e-3);
  EXPECT_LT(RotationAngleBetween(truth, r.pose) * 180.0 / M_PI, 0.1);
  EXPECT_GT(r.valid_rays, r.rays * 0.9);
}

// A frame between keyframes, from a smaller offset: within 2 mm (measured 0.9 mm).
TEST_F(TrackerTest, TracksAHeldOutFrame) {
  const SE3 truth = *dataset_->frames()[15].ground_truth;
  Vector6d offset;
  offset << 0.01, 0.008, -0.012, -0.01, 0.006, 0.008;
  const TrackingResult r = TrackFrom(truth * SE3::Exp(offset), 15, TrackerOptions());
  EXPECT_EQ(r.state, TrackingState::kOk) << r.reason;
  EXPECT_LT((truth.Inverse() * r.pose).translation().norm(), 2e-3);
  EXPECT_LT(RotationAngleBetween(truth, r.pose) * 180.0 / M_PI, 0.1);
}

TEST_F(TrackerTest, AFrameFarFromTheMapIsLostAndKeepsThePrediction) {
  // Far outside the mapped room, looking away from it.
  Vector6d away;
  away << 0, 0, -30.0, 0, 3.0, 0;
  const SE3 start = SE3::Exp(away);
  const TrackingResult r = TrackFrom(start, 15, TrackerOptions());
  EXPECT_EQ(r.state, TrackingState::kLost);
  EXPECT_NE(r.reason.find("too few valid rays"), std::string::npos) << r.reason;
  EXPECT_LT((start.Inverse() * r.pose).translation().norm(), 1e-12);  // not a made-up estimate
}

TEST_F(TrackerTest, AWrongFrameSizeIsLost) {
  RgbdFrame small;
  small.color = ColorImage(8, 6, 3);
  small.depth = DepthImage(8, 6, 1);
  Tracker tracker(map_, backend_, TrackerOptions());
  tracker.Reset(SE3(), 0.0);
  const TrackingResult r = tracker.Track(small, dataset_->calibration().pinhole).value();
  EXPECT_EQ(r.state, TrackingState::kLost);
  EXPECT_NE(r.reason.find("size"), std::string::npos) << r.reason;
}

// The paper's Adam tracker moves towards the truth but needs its 90 small steps.
TEST_F(TrackerTest, AdamModeImprovesTheInitialGuess) {
  const SE3 truth = *dataset_->frames()[10].ground_truth;
  Vector6d offset;
  offset << 0.01, -0.01, 0.005, 0.0, 0.0, 0.0;
  TrackerOptions options;
  options.mode = TrackingMode::kAdam;
  options.iterations = 90;
  options.rays = 2048;
  const SE3 start = truth * SE3::Exp(offset);
  const TrackingResult r = TrackFrom(start, 10, options);
  EXPECT_NE(r.state, TrackingState::kLost) << r.reason;
  EXPECT_LT((truth.Inverse() * r.pose).translation().norm(),
            0.5 * (truth.Inverse() * start).translation().norm());
}

TEST_F(TrackerTest, TracksTheWholeSequenceWithConstantVelocity) {
  TrackerOptions options;
  options.rays = 2048;
  auto result = TrackDataset(*dataset_, *map_, *backend_, options);
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_EQ(result->trajectory.size(), 30u);
  EXPECT_EQ(result->lost, 0);
  double worst = 0.0;
  for (int i = 0; i < 30; ++i) {
    const SE3& truth = *dataset_->frames()[i].ground_truth;
    worst = std::max(worst, (truth.Inverse() * result->trajectory[i].pose).translation().norm());
  }
  EXPECT_LT(worst, 5e-3);
}

// A time budget shorter than any iteration leaves the schedule's two iterations that always
// run (the coarse level's first, the fine level's first, which classifies the frame) and says
// the budget ended it; without one the same frame runs the schedule (it starts 5 cm off, so it
// does not converge in two steps) and is not marked.
TEST_F(TrackerTest, ATimeBudgetEndsTheScheduleAfterEachLevelsFirstIteration) {
  TrackerOptions options;
  options.iterations = 16;
  const TrackingResult full = TrackFrom(PerturbedPose(10), 10, options);
  EXPECT_FALSE(full.out_of_time);
  EXPECT_GT(full.iterations, 4);
  options.time_budget_ms = 1e-6;
  const TrackingResult cut = TrackFrom(PerturbedPose(10), 10, options);
  EXPECT_TRUE(cut.out_of_time);
  EXPECT_EQ(cut.iterations, 2);
  EXPECT_EQ(cut.rays, full.rays);
}

TEST(TrackerOptionsTest, RejectsBadOptions) {
  TrackerOptions o;
  o.rays = 3;
  EXPECT_FALSE(Tracker::ValidateOptions(o).ok());
  o = TrackerOptions();
  o.params.use_color = o.params.use_depth = false;
  EXPECT_FALSE(Tracker::ValidateOptions(o).ok());
  o = TrackerOptions();
  o.time_budget_ms = -1.0;
  EXPECT_FALSE(Tracker::ValidateOptions(o).ok());
}

}  // namespace
}  // namespace plx

#include "core/mapping/mapping_session.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

// Shorter than any piece: every slice runs exactly one piece of work.
constexpr double kTinySlice = 1e-9;

// The same bricks with the same values and the same cell occupancy, bit for bit (fusion slices
// are exact: nothing may differ, not even in the last bit). Brick by coordinate, not by slot: a
// keyframe's brick list comes from a hash set whose order abseil salts per table, so two
// mappers store the same bricks in different slots, with or without slices.
void ExpectSameMap(const PlenoxelMap& expected, const PlenoxelMap& actual) {
  const SparseGrid& e = expected.grid;
  const SparseGrid& a = actual.grid;
  ASSERT_EQ(a.num_bricks(), e.num_bricks());
  EXPECT_EQ(a.index_min(), e.index_min());
  EXPECT_EQ(a.index_dims(), e.index_dims());
  int64_t differing_bricks = 0;
  for (int64_t slot = 0; slot < e.num_bricks(); ++slot) {
    const int32_t other = a.FindBrick(e.brick_coords()[slot]);
    ASSERT_GE(other, 0) << "brick of slot " << slot << " missing";
    const bool same =
        std::equal(e.brick_density(slot), e.brick_density(slot) + kBrickVertices,
                   a.brick_density(other)) &&
        std::equal(e.brick_sh(slot), e.brick_sh(slot) + kBrickVertices * kShCoeffCount,
                   a.brick_sh(other));
    differing_bricks += same ? 0 : 1;
  }
  EXPECT_EQ(differing_bricks, 0) << "bricks whose densities or SH differ";
  EXPECT_EQ(a.occupancy_stale(), e.occupancy_stale());
  ASSERT_EQ(a.num_active_blocks(), e.num_active_blocks());
  const GridView ev = e.view(), av = a.view();
  int64_t differing_blocks = 0;
  for (const int64_t block : e.active_blocks()) {
    ASSERT_GE(av.block_cells[block], 0) << "block " << block << " inactive";
    differing_blocks += std::equal(ev.cell_bits + ev.block_cells[block],
                                   ev.cell_bits + ev.block_cells[block] + kBrickEdge,
                                   av.cell_bits + av.block_cells[block])
                            ? 0
                            : 1;
  }
  EXPECT_EQ(differing_blocks, 0) << "blocks whose cell occupancy differs";
}

// The synthetic room at a small size: keyframes 0, 10 and 20 of a 30-frame sequence.
class MappingSessionTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dataset_ = testing::MakeSyntheticRoom(96, 72, 30).release();
    ASSERT_NE(dataset_, nullptr);
  }
  static void TearDownTestSuite() {
    delete dataset_;
    dataset_ = nullptr;
  }

  void SetUp() override { backend_ = MakeCpuBackend(2); }

  static MappingSessionOptions Options() {
    MappingSessionOptions o;
    o.mapper = MapperOptionsForVoxelSize(0.03f);
    o.mapper.batch_size = 2048;
    o.iterations_per_keyframe = 30;
    o.chunk_iterations = 5;
    o.min_publish_interval_s = 0.0;
    o.publish_every_iterations = 10;
    return o;
  }

  static absl::Status AddKeyframe(MappingSession& session, int index) {
    const RgbdFrame& f = dataset_->frames()[index];
    return session.AddKeyframe(f, *f.ground_truth, dataset_->calibration().pinhole);
  }

  // Steps until the session has no work, checking that every step stays bounded.
  static void RunToEnd(MappingSession& session, const MappingSessionOptions& o) {
    for (int guard = 0; session.has_work() && guard < 1000; ++guard) {
      absl::StatusOr<MappingStepResult> step = session.Step(/*finish=*/true);
      ASSERT_TRUE(step.ok()) << step.status();
      EXPECT_LE(step->keyframes_integrated, 1);
      EXPECT_LE(step->iterations, o.chunk_iterations);
    }
    ASSERT_FALSE(session.has_work());
  }

  // One thread: the optimiser's gradient scatter is then in a fixed order, so two mappers
  // given the same work agree bit for bit (integration slices against one integration).
  static std::unique_ptr<Backend> DeterministicBackend() { return MakeCpuBackend(1); }

  static MapperOptions SliceMapperOptions() {
    MapperOptions o = MapperOptionsForVoxelSize(0.03f);
    o.max_iterations = 20;
    o.batch_size = 1024;
    return o;
  }

  static absl::Status AddKeyframe(Mapper& mapper, int index) {
    const RgbdFrame& f = dataset_->frames()[index];
    return mapper.AddKeyframe(f, *f.ground_truth, dataset_->calibration().pinhole);
  }

  // Integrates the keyframes added to `mapper` in tiny slices; returns how many it took.
  static int IntegrateInTinySlices(Mapper& mapper) {
    int slices = 0;
    for (;;) {
      absl::StatusOr<bool> done = mapper.IntegrateSlice(kTinySlice);
      EXPECT_TRUE(done.ok()) << done.status();
      ++slices;
      if (!done.ok() || *done || slices > 100000) break;
      EXPECT_TRUE(mapper.integrating());
    }
    EXPECT_FALSE(mapper.integrating());
    return slices;
  }

  // Steps until a step publishes a version: a keyframe's integration may take several steps,
  // and its first chunk of iterations comes before the version.
  static absl::StatusOr<MappingStepResult> StepUntilPublished(MappingSession& session) {
    for (int guard = 0; guard < 10000; ++guard) {
      absl::StatusOr<MappingStepResult> step = session.Step();
      if (!step.ok() || step->published != nullptr) return step;
    }
    return absl::DeadlineExceededError("no version published in 10000 steps");
  }

  static InMemoryDataset* dataset_;
  std::unique_ptr<Backend> backend_;
};
InMemoryDataset* MappingSessionTest::dataset_ = nullptr;

TEST_F(MappingSessionTest, EachKeyframeEarnsItsBudgetAndTheLastVersionIsPublished) {
  const MappingSessionOptions o = Options();
  auto session = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  for (int f : {0, 10, 20}) ASSERT_TRUE(AddKeyframe(**session, f).ok());
  EXPECT_EQ((*session)->pending_keyframes(), 3);
  RunToEnd(**session, o);
  const MappingSessionProgress p = (*session)->progress();
  EXPECT_EQ(p.keyframes_integrated, 3);
  EXPECT_EQ(p.iterations, 3 * o.iterations_per_keyframe);
  EXPECT_DOUBLE_EQ(p.fraction, 1.0);
  ASSERT_NE((*session)->latest(), nullptr);
  EXPECT_GT(p.published_versions, 1);
  EXPECT_FALSE((*session)->latest()->grid.occupancy_stale());

  // The final version is a good map of the held-out frames (29.9 dB measured at 90 iterations).
  MapEvalOptions eval;
  eval.pixels_per_frame = 0;
  auto metrics = EvaluateMap(*backend_, *(*session)->latest(), *dataset_, {5, 15, 25}, eval);
  ASSERT_TRUE(metrics.ok()) << metrics.status();
  EXPECT_GT(metrics->psnr, 26.0) << "measured " << metrics->psnr;
}

TEST_F(MappingSessionTest, OnlyKeyframesThatEarnIterationsAddToTheBudget) {
  const MappingSessionOptions o = Options();
  auto session = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  const PinholeIntrinsics& k = dataset_->calibration().pinhole;
  for (int f : {0, 10}) {
    const RgbdFrame& frame = dataset_->frames()[f];
    ASSERT_TRUE((*session)->AddKeyframe(frame, *frame.ground_truth, k, false).ok());
  }
  // Fused, but with nothing earned there is nothing to optimise (a zero budget is not "no
  // limit").
  RunToEnd(**session, o);
  MappingSessionProgress p = (*session)->progress();
  EXPECT_EQ(p.keyframes_integrated, 2);
  EXPECT_EQ(p.iteration_budget, 0);
  EXPECT_EQ(p.iterations, 0);
  ASSERT_NE((*session)->latest(), nullptr);
  EXPECT_GT((*session)->latest()->grid.num_bricks(), 0);

  ASSERT_TRUE(AddKeyframe(**session, 20).ok());
  RunToEnd(**session, o);
  p = (*session)->progress();
  EXPECT_EQ(p.keyframes_integrated, 3);
  EXPECT_EQ(p.iteration_budget, o.iterations_per_keyframe);
  EXPECT_EQ(p.iterations, o.iterations_per_keyframe);
}

TEST_F(MappingSessionTest, PublishedVersionsNeverChangeAndShareUnchangedBricks) {
  const MappingSessionOptions o = Options();
  auto session = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_TRUE(AddKeyframe(**session, 0).ok());
  absl::StatusOr<MappingStepResult> first = StepUntilPublished(**session);
  ASSERT_TRUE(first.ok()) << first.status();
  // The first keyframe is published once integrated and given its first chunk: a reader (a
  // tracker) needs a map to start.
  ASSERT_NE(first->published, nullptr);
  EXPECT_EQ(first->keyframes_in_published, 1);
  const std::shared_ptr<const PlenoxelMap> v1 = first->published;
  const std::vector<float> v1_density = v1->grid.DensityValues();
  const std::vector<float> v1_sh = v1->grid.ShValues();

  ASSERT_TRUE(AddKeyframe(**session, 20).ok());
  RunToEnd(**session, o);
  const std::shared_ptr<const PlenoxelMap> last = (*session)->latest();
  ASSERT_NE(last, v1);
  EXPECT_GT(last->grid.num_bricks(), v1->grid.num_bricks()) << "keyframe 20 sees new space";
  EXPECT_TRUE(v1->grid.DensityValues() == v1_density) << "a published version changed";
  EXPECT_TRUE(v1->grid.ShValues() == v1_sh);
  // Writes after a publish cloned bricks instead of changing the shared ones.
  EXPECT_GT((*session)->progress().cloned_bricks, 0);
  std::vector<float> last_density = last->grid.DensityValues();
  last_density.resize(v1_density.size());  // the bricks v1 has, in the same slots
  EXPECT_FALSE(last_density == v1_density)
      << "the optimiser should have changed the first keyframe's bricks since";
}

TEST_F(MappingSessionTest, ClonesPerIterationAreBoundedAndDeferredBricksCatchUp) {
  MappingSessionOptions o = Options();
  o.chunk_iterations = 1;
  o.max_clones_per_iteration = 5;
  auto session = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_TRUE(AddKeyframe(**session, 0).ok());
  absl::StatusOr<MappingStepResult> first = StepUntilPublished(**session);
  ASSERT_TRUE(first.ok() && first->published != nullptr);
  const std::shared_ptr<const PlenoxelMap> v1 = first->published;
  const std::vector<float> v1_density = v1->grid.DensityValues();
  int64_t cloned = (*session)->progress().cloned_bricks;
  int steps = 0;
  while ((*session)->has_work()) {
    ASSERT_TRUE((*session)->Step().ok());
    const int64_t now = (*session)->progress().cloned_bricks;
    EXPECT_LE(now - cloned, 5) << "step " << steps;
    cloned = now;
    ++steps;
  }
  EXPECT_GT(cloned, 5) << "bricks deferred by one step are cloned by later ones";
  EXPECT_TRUE(v1->grid.DensityValues() == v1_density);
  // Deferred bricks still learn: the map moved away from the first version everywhere it was
  // observed, not only in the first few cloned bricks.
  const std::vector<float> last = (*session)->latest()->grid.DensityValues();
  int64_t changed_bricks = 0;
  for (int64_t b = 0; b < v1->grid.num_bricks(); ++b) {
    for (int i = 0; i < kBrickVertices; ++i) {
      if (last[b * kBrickVertices + i] != v1_density[b * kBrickVertices + i]) {
        ++changed_bricks;
        break;
      }
    }
  }
  EXPECT_GT(changed_bricks, 10);
}

TEST_F(MappingSessionTest, TheLearningRateDoesNotRestartWhenAKeyframeArrivesLate) {
  const MappingSessionOptions o = Options();
  auto session = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  ASSERT_TRUE(AddKeyframe(**session, 0).ok());
  RunToEnd(**session, o);
  const double after_first = (*session)->progress().schedule;
  EXPECT_NEAR(after_first, 1.0, 1.0 / o.iterations_per_keyframe + 1e-9);
  // The budget doubles; the schedule must hold where it was, not fall back to 0.5.
  ASSERT_TRUE(AddKeyframe(**session, 10).ok());
  double lowest = 1.0;
  for (int guard = 0; (*session)->has_work() && guard < 100; ++guard) {
    ASSERT_TRUE((*session)->Step().ok());
    lowest = std::min(lowest, (*session)->progress().schedule);
  }
  EXPECT_GE(lowest, after_first);
}

TEST_F(MappingSessionTest, ContinuingAMapLeavesTheBaseVersionAsItWas) {
  const MappingSessionOptions o = Options();
  auto first = MappingSession::Create(o, backend_.get(), nullptr);
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE(AddKeyframe(**first, 0).ok());
  RunToEnd(**first, o);
  const std::shared_ptr<const PlenoxelMap> base = (*first)->latest();
  const std::vector<float> base_density = base->grid.DensityValues();

  auto second = MappingSession::Create(o, backend_.get(), base);
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ((*second)->latest(), base);
  ASSERT_TRUE(AddKeyframe(**second, 10).ok());
  RunToEnd(**second, o);
  EXPECT_NE((*second)->latest(), base);
  EXPECT_GE((*second)->latest()->grid.num_bricks(), base->grid.num_bricks());
  EXPECT_TRUE(base->grid.DensityValues() == base_density);
}

TEST_F(MappingSessionTest, RejectsBadKeyframesAndOptions) {
  MappingSessionOptions o = Options();
  o.iterations_per_keyframe = 0;
  EXPECT_EQ(MappingSession::Create(o, backend_.get(), nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
  o = Options();
  o.chunk_seconds = 0.0;
  EXPECT_EQ(MappingSession::Create(o, backend_.get(), nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);

  auto session = MappingSession::Create(Options(), backend_.get(), nullptr);
  ASSERT_TRUE(session.ok());
  PinholeIntrinsics wrong = dataset_->calibration().pinhole;
  wrong.width += 1;
  const RgbdFrame& f = dataset_->frames()[0];
  EXPECT_EQ((*session)->AddKeyframe(f, *f.ground_truth, wrong).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((*session)->pending_keyframes(), 0);
  EXPECT_FALSE((*session)->has_work());
}

// Two keyframes with optimisation between them: the second integration grows optimiser buffers
// that already hold gradients and RMSProp state, which must come through the piecewise copy.
TEST_F(MappingSessionTest, IntegrationSlicesGiveTheMapOfOneIntegrationBitForBit) {
  const std::unique_ptr<Backend> backend = DeterministicBackend();
  Mapper whole(SliceMapperOptions(), backend.get());
  Mapper sliced(SliceMapperOptions(), backend.get());
  for (int keyframe : {0, 10}) {
    SCOPED_TRACE(keyframe);
    ASSERT_TRUE(AddKeyframe(whole, keyframe).ok());
    ASSERT_TRUE(AddKeyframe(sliced, keyframe).ok());
    ASSERT_TRUE(whole.AllocateAndInitialize().ok());
    const int before = sliced.integrated_keyframes();
    const int slices = IntegrateInTinySlices(sliced);
    EXPECT_GT(slices, 10) << "listing, allocation runs, fusion ranges, occupancy, buffers";
    EXPECT_EQ(sliced.integrated_keyframes(), before + 1);
    ExpectSameMap(whole.map(), sliced.map());

    ASSERT_TRUE(whole.Optimize(nullptr, 10).ok());
    ASSERT_TRUE(sliced.Optimize(nullptr, 10).ok());
    EXPECT_EQ(sliced.iterations_done(), whole.iterations_done());
    ExpectSameMap(whole.map(), sliced.map());
  }
}

TEST_F(MappingSessionTest, AHalfIntegratedMapIsNeitherPublishedNorOptimised) {
  const std::unique_ptr<Backend> backend = DeterministicBackend();
  Mapper whole(SliceMapperOptions(), backend.get());
  ASSERT_TRUE(AddKeyframe(whole, 0).ok());
  ASSERT_TRUE(whole.AllocateAndInitialize().ok());

  Mapper sliced(SliceMapperOptions(), backend.get());
  ASSERT_TRUE(AddKeyframe(sliced, 0).ok());
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(sliced.IntegrateSlice(kTinySlice).ok());
  ASSERT_TRUE(sliced.integrating());
  // Publishing finishes the integration first: the version has every brick fused.
  absl::StatusOr<std::shared_ptr<const PlenoxelMap>> version = sliced.Publish();
  ASSERT_TRUE(version.ok()) << version.status();
  EXPECT_FALSE(sliced.integrating());
  EXPECT_EQ(sliced.integrated_keyframes(), 1);
  ExpectSameMap(whole.map(), **version);

  // So does optimising.
  ASSERT_TRUE(AddKeyframe(whole, 10).ok());
  ASSERT_TRUE(AddKeyframe(sliced, 10).ok());
  ASSERT_TRUE(sliced.IntegrateSlice(kTinySlice).ok());
  ASSERT_TRUE(sliced.integrating());
  ASSERT_TRUE(whole.Optimize(nullptr, 3).ok());
  ASSERT_TRUE(sliced.Optimize(nullptr, 3).ok());
  EXPECT_FALSE(sliced.integrating());
  EXPECT_EQ(sliced.iterations_done(), 3);
  ExpectSameMap(whole.map(), sliced.map());
}

MappingSessionOptions SliceSessionOptions(double chunk_seconds) {
  MappingSessionOptions o;
  o.mapper = MapperOptionsForVoxelSize(0.03f);
  o.mapper.batch_size = 1024;
  o.iterations_per_keyframe = 10;
  o.chunk_iterations = 1;  // the same chunks whatever chunk_seconds
  o.chunk_seconds = chunk_seconds;
  o.min_publish_interval_s = 0.0;
  o.publish_every_iterations = 5;
  o.max_clones_per_iteration = 0;  // publishing at other moments must not defer any update
  return o;
}

TEST_F(MappingSessionTest, StepsIntegrateInSlicesWithoutOptimisingOrPublishing) {
  const std::unique_ptr<Backend> backend = DeterministicBackend();
  auto tiny = MappingSession::Create(SliceSessionOptions(kTinySlice), backend.get(), nullptr);
  auto roomy = MappingSession::Create(SliceSessionOptions(10.0), backend.get(), nullptr);
  ASSERT_TRUE(tiny.ok() && roomy.ok());
  MappingSession& sliced = **tiny;
  MappingSession& whole = **roomy;

  for (int keyframe : {0, 10}) {
    SCOPED_TRACE(keyframe);
    ASSERT_TRUE(AddKeyframe(sliced, keyframe).ok());
    ASSERT_TRUE(AddKeyframe(whole, keyframe).ok());
    const int integrated = sliced.progress().keyframes_integrated;

    // With room for it, one step integrates the keyframe, and does nothing else.
    absl::StatusOr<MappingStepResult> one = whole.Step();
    ASSERT_TRUE(one.ok()) << one.status();
    EXPECT_EQ(one->keyframes_integrated, 1);
    EXPECT_EQ(one->iterations, 0);
    EXPECT_EQ(one->published, nullptr) << "published before the keyframe's first chunk";

    int steps = 0;
    absl::StatusOr<MappingStepResult> step;
    for (;;) {
      step = sliced.Step();
      ASSERT_TRUE(step.ok()) << step.status();
      ++steps;
      EXPECT_EQ(step->iterations, 0) << "step " << steps << " optimised while integrating";
      if (step->keyframes_integrated > 0) break;
      EXPECT_EQ(step->published, nullptr) << "step " << steps << " published unfused bricks";
      EXPECT_EQ(sliced.progress().keyframes_integrated, integrated);
      EXPECT_TRUE(sliced.has_work());
      ASSERT_LT(steps, 100000);
    }
    EXPECT_GT(steps, 10);
    EXPECT_EQ(sliced.progress().keyframes_integrated, integrated + 1);
    EXPECT_EQ(step->published, nullptr) << "published before the keyframe's first chunk";
    // The next steps of each are the keyframe's iterations_after_integration (one iteration a
    // chunk): no version and no next keyframe before the last of them, then the version is due.
    const int owed = SliceSessionOptions(10.0).iterations_after_integration;
    ASSERT_GE(owed, 2);
    absl::StatusOr<MappingStepResult> whole_chunk, sliced_chunk;
    for (int chunk = 1; chunk <= owed; ++chunk) {
      SCOPED_TRACE(chunk);
      whole_chunk = whole.Step();
      sliced_chunk = sliced.Step();
      ASSERT_TRUE(whole_chunk.ok() && sliced_chunk.ok());
      EXPECT_EQ(sliced_chunk->iterations, 1);
      EXPECT_EQ(whole_chunk->iterations, 1);
      if (chunk < owed) {
        EXPECT_EQ(whole_chunk->published, nullptr) << "published before the keyframe's iterations";
        EXPECT_EQ(sliced_chunk->published, nullptr);
      }
    }
    ASSERT_NE(whole_chunk->published, nullptr);
    ASSERT_NE(sliced_chunk->published, nullptr);
    ExpectSameMap(*whole_chunk->published, *sliced_chunk->published);

    // The budgets run out the same way, whatever the chunks.
    while (whole.has_work()) ASSERT_TRUE(whole.Step(/*finish=*/true).ok());
    while (sliced.has_work()) ASSERT_TRUE(sliced.Step(/*finish=*/true).ok());
    EXPECT_EQ(sliced.progress().iterations, whole.progress().iterations);
    ExpectSameMap(*whole.latest(), *sliced.latest());
  }
}

TEST_F(MappingSessionTest, AQueuedKeyframeWaitsForTheIterationsOfTheOneIntegratedBeforeIt) {
  // Fused but unfitted map is what trackers slide on: the keyframe just integrated gets its
  // iterations_after_integration before anything else, even with another keyframe waiting.
  const std::unique_ptr<Backend> backend = DeterministicBackend();
  const MappingSessionOptions options = SliceSessionOptions(10.0);  // one iteration a chunk
  auto created = MappingSession::Create(options, backend.get(), nullptr);
  ASSERT_TRUE(created.ok()) << created.status();
  MappingSession& session = **created;
  ASSERT_TRUE(AddKeyframe(session, 0).ok());
  ASSERT_TRUE(AddKeyframe(session, 10).ok());
  absl::StatusOr<MappingStepResult> step = session.Step();
  ASSERT_TRUE(step.ok()) << step.status();
  ASSERT_EQ(step->keyframes_integrated, 1);
  for (int chunk = 1; chunk <= options.iterations_after_integration; ++chunk) {
    step = session.Step();
    ASSERT_TRUE(step.ok()) << step.status();
    EXPECT_EQ(step->keyframes_integrated, 0) << "chunk " << chunk;
    EXPECT_EQ(step->iterations, 1) << "chunk " << chunk;
    EXPECT_EQ(session.progress().keyframes_integrated, 1) << "chunk " << chunk;
  }
  step = session.Step();
  ASSERT_TRUE(step.ok()) << step.status();
  EXPECT_EQ(step->keyframes_integrated, 1) << "the queued keyframe comes next";
  EXPECT_EQ(step->iterations, 0);

  MappingSessionOptions bad = options;
  bad.iterations_after_integration = 0;
  EXPECT_EQ(MappingSession::Create(bad, backend.get(), nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plx

#include "core/eval/map_metrics.h"

#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/synthetic/synthetic_sequence.h"

namespace plx {
namespace {

TEST(MapMetricsTest, HeldOutAndKeyframeIndices) {
  EXPECT_EQ(KeyframeIndices(25, 10), (std::vector<int>{0, 10, 20}));
  EXPECT_EQ(HeldOutFrames(25, 10), (std::vector<int>{5, 15}));
  EXPECT_EQ(HeldOutFrames(126, 10, 3), (std::vector<int>{5, 45, 85}));
  EXPECT_EQ(HeldOutFrames(4, 1).size(), 4u);
}

// A map with nothing in it: no pixel is rendered, PSNR compares against the background.
TEST(MapMetricsTest, EmptyMapHasZeroCoverage) {
  SyntheticOptions o;
  o.width = 64;
  o.height = 48;
  o.num_frames = 6;
  auto dataset = GenerateSyntheticSequence(o);
  ASSERT_TRUE(dataset.ok());
  PlenoxelMap map(0.05f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  MapEvalOptions options;
  options.pixels_per_frame = 500;
  auto r = EvaluateMap(*backend, map, *dataset, {1, 3}, options);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->frames, 2);
  EXPECT_EQ(r->pixels, 1000);
  EXPECT_EQ(r->coverage, 0.0);
  EXPECT_GT(r->psnr, 0.0);
  EXPECT_LT(r->psnr, 20.0);
}

TEST(MapMetricsTest, BadFramesAreErrors) {
  SyntheticOptions o;
  o.width = 32;
  o.height = 24;
  o.num_frames = 2;
  auto dataset = GenerateSyntheticSequence(o);
  ASSERT_TRUE(dataset.ok());
  PlenoxelMap map(0.05f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  EXPECT_EQ(EvaluateMap(*backend, map, *dataset, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(EvaluateMap(*backend, map, *dataset, {7}).status().code(),
            absl::StatusCode::kOutOfRange);
}

}  // namespace
}  // namespace plx

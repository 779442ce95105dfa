// RmsPropStep with several work items per brick (the GPU's launch shape) must do exactly what
// one item per brick does: the update is per vertex, so the results are bit-identical.
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>

#include "core/common/unified_allocator.h"
#include "core/cpu/cpu_backend.h"
#include "core/kernels/backend.h"
#include "core/mapping/map_dataset.h"
#include "core/mapping/training_set.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/grad_buffers.h"

namespace plx {
namespace {

using testing::GradBuffers;

TEST(RmsPropSlicesTest, SlicedBricksGiveTheSameUpdateAsWholeBricks) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  SyntheticOptions o;
  o.width = 96;
  o.height = 72;
  o.num_frames = 11;
  absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(o);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  MapperOptions options = MapperOptionsForVoxelSize(0.03f);
  options.max_iterations = 5;
  options.batch_size = 4096;
  absl::StatusOr<MapDatasetResult> mapped = MapDataset(*dataset, {0, 10}, options, *backend);
  ASSERT_TRUE(mapped.ok()) << mapped.status();
  PlenoxelMap& map = *mapped->map;

  TrainingSet set;
  for (int f : {0, 10}) {
    const RgbdFrame& frame = dataset->frames()[f];
    ASSERT_TRUE(
        set.AddFrame(frame, *frame.ground_truth, dataset->calibration().pinhole, 10.0).ok());
  }
  MappingBatchParams batch;
  batch.seed = 7;
  batch.batch_size = 4096;
  batch.render = map.render;
  GradBuffers grads(map.grid);
  UnifiedVector<MappingRayLoss> losses(batch.batch_size);
  ASSERT_TRUE(backend
                  ->MappingForwardBackward(map.grid.view(), grads.view(), set.rays_view(), batch,
                                           losses.data())
                  .ok());
  ASSERT_GT(std::count(grads.touched.begin(), grads.touched.end(), 1), 1000);

  const int64_t n = map.grid.num_vertices();
  // Copy-on-write copies: each clones the bricks a step writes, as the mapper does, so `map`
  // itself must come out unchanged.
  const std::vector<float> map_density = map.grid.DensityValues();
  PlenoxelMap whole = map.ShareCopy(), sliced = map.ShareCopy();
  UnifiedVector<float> rms_dw(n, 0.0f), rms_sw(n * kShCoeffCount, 0.0f);
  UnifiedVector<float> rms_ds(n, 0.0f), rms_ss(n * kShCoeffCount, 0.0f);
  RmsPropParams params;
  params.lr_density = 5.0f;
  params.sigma_threshold = map.render.sigma_threshold;
  for (int step = 0; step < 2; ++step) {
    GradBuffers gw = grads, gs = grads;
    params.brick_slices = 1;
    whole.grid.MakePrivate(gw.brick_touched.data());
    ASSERT_TRUE(backend
                    ->RmsPropStep(whole.grid.view(), whole.grid.write_view(), gw.view(),
                                  {rms_dw.data(), rms_sw.data()}, params)
                    .ok());
    params.brick_slices = 64;
    sliced.grid.MakePrivate(gs.brick_touched.data());
    ASSERT_TRUE(backend
                    ->RmsPropStep(sliced.grid.view(), sliced.grid.write_view(), gs.view(),
                                  {rms_ds.data(), rms_ss.data()}, params)
                    .ok());
    EXPECT_EQ(std::count(gs.touched.begin(), gs.touched.end(), 0), n) << "touched flags cleared";
    EXPECT_EQ(std::count(gs.brick_touched.begin(), gs.brick_touched.end(), 0),
              static_cast<std::ptrdiff_t>(gs.brick_touched.size()));
    EXPECT_TRUE(gs.sh == gw.sh) << "SH gradients cleared alike";
  }
  EXPECT_TRUE(whole.grid.DensityValues() == sliced.grid.DensityValues());
  EXPECT_TRUE(whole.grid.ShValues() == sliced.grid.ShValues());
  EXPECT_TRUE(rms_dw == rms_ds);
  EXPECT_TRUE(rms_sw == rms_ss);
  EXPECT_FALSE(whole.grid.DensityValues() == map_density) << "the steps changed the copy";
  EXPECT_TRUE(map.grid.DensityValues() == map_density) << "the shared original is unchanged";
}

}  // namespace
}  // namespace plx

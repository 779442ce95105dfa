// Behaviour every backend must have, run once per backend (CPU always, CUDA when a device is
// visible; skipped with the reason otherwise).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/eval/map_metrics.h"
#include "core/kernels/tracking_terms.h"
#include "core/mapping/map_dataset.h"
#include "core/render/render_view.h"
#include "core/synthetic/synthetic_sequence.h"
#include "core/tracking/tracker.h"
#include "tests/backend_test_util.h"

namespace plx {
namespace {

using ReduceTest = testing::BackendTest;
using PipelineTest = testing::BackendTest;

// The backend's reduction equals a plain serial sum of the shared per-ray math, for counts that
// are not multiples of any block size and beyond the CUDA reduction's grid (256 x 256 rays),
// with rays left out (weight 0) and both losses. Double sums of <= 1e5 terms: 1e-9 relative.
TEST_P(ReduceTest, ReduceTrackingTermsEqualsTheSerialSum) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int64_t count : {int64_t{1}, int64_t{1000}, int64_t{70001}}) {
    UnifiedVector<TrackingRayTerm> terms(count);
    for (TrackingRayTerm& t : terms) {
      for (int r = 0; r < kTrackingResiduals; ++r) {
        t.residual[r] = 3.0f * u(rng);
        t.weight[r] = u(rng) < -0.8f ? 0.0f : 1.0f + u(rng) * 0.5f;
        for (int k = 0; k < kPoseDim; ++k) t.jacobian[r][k] = u(rng);
      }
    }
    const float scale[2] = {1.2f, 0.7f};
    for (TrackingLoss loss : {TrackingLoss::kHuber, TrackingLoss::kL1}) {
      TrackingSums serial;
      serial.Clear();
      for (const TrackingRayTerm& t : terms) {
        AccumulateTrackingTerm(t, loss, 1.345f, scale, &serial);
      }
      TrackingSums s;
      ASSERT_TRUE(backend().ReduceTrackingTerms(terms.data(), count, loss, 1.345f, scale, &s).ok());
      auto near = [](double a, double b) {
        return std::fabs(a - b) <= 1e-9 * (1.0 + std::fabs(b));
      };
      for (int i = 0; i < kNormalUpper; ++i) EXPECT_PRED2(near, s.H[i], serial.H[i]) << i;
      for (int i = 0; i < kPoseDim; ++i) EXPECT_PRED2(near, s.g[i], serial.g[i]) << i;
      EXPECT_PRED2(near, s.cost, serial.cost);
      EXPECT_PRED2(near, s.residual_sq, serial.residual_sq);
      EXPECT_EQ(s.residual_count, serial.residual_count);
      EXPECT_EQ(s.valid_rays, serial.valid_rays);
    }
  }
}

// Map three keyframes of the synthetic room, render a held-out view, track a perturbed frame:
// the whole pipeline on one backend (measured on the CPU: PSNR 34.1 dB, tracking error 1.6 mm
// from a 1.6 cm / 0.8 degree start; the bounds leave room for the other backend's rounding).
TEST_P(PipelineTest, MapsRendersAndTracksTheSyntheticRoom) {
  SyntheticOptions o;
  o.width = 96;
  o.height = 72;
  o.num_frames = 21;
  absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(o);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  MapperOptions m = MapperOptionsForVoxelSize(0.03f);
  m.max_iterations = 60;
  m.batch_size = 4096;
  absl::StatusOr<MapDatasetResult> mapped = MapDataset(*dataset, {0, 10, 20}, m, backend());
  ASSERT_TRUE(mapped.ok()) << mapped.status();
  PlenoxelMap& map = *mapped->map;
  const PinholeIntrinsics& k = dataset->calibration().pinhole;

  const RgbdFrame& held_out = dataset->frames()[5];
  absl::StatusOr<RenderedView> rendered = RenderView(backend(), map, *held_out.ground_truth, k);
  ASSERT_TRUE(rendered.ok()) << rendered.status();
  const RenderedView& view = *rendered;
  double se = 0.0;
  for (size_t i = 0; i < view.color.data.size(); ++i) {
    const double e = view.color.data[i] - held_out.color.data[i];
    se += e * e;
  }
  const double psnr = -10.0 * std::log10(se / view.color.data.size());
  EXPECT_GT(psnr, 28.0);

  const RgbdFrame& frame = dataset->frames()[10];
  Vector6d offset;
  offset << 0.01, -0.01, 0.008, 0.01, -0.006, 0.008;
  const SE3 start = *frame.ground_truth * SE3::Exp(offset);
  Tracker tracker(&map, &backend(), TrackerOptions());
  tracker.Reset(start, frame.timestamp - 1.0 / 30);
  absl::StatusOr<TrackingResult> tracked = tracker.Track(frame, k, start);
  ASSERT_TRUE(tracked.ok()) << tracked.status();
  const TrackingResult& r = *tracked;
  EXPECT_EQ(r.state, TrackingState::kOk) << r.reason;
  EXPECT_LT((frame.ground_truth->Inverse() * r.pose).translation().norm(), 5e-3);
}

PLX_INSTANTIATE_BACKEND_SUITE(ReduceTest);
PLX_INSTANTIATE_BACKEND_SUITE(PipelineTest);

}  // namespace
}  // namespace plx

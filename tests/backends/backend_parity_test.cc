// CUDA-vs-CPU parity: the same inputs through both backends' kernels on a small synthetic map.
// Skipped (with the reason) when no CUDA device is visible.
//
// Why results differ at all: both backends run the same per-ray float code, but nvcc contracts
// a * b + c into fused multiply-adds (one rounding instead of two) and the device's expf/logf
// differ from glibc's by an ulp or two, so each float operation may differ by ~1e-7 relative.
// Along a ray of at most a few hundred samples that grows to ~1e-5 relative; every tolerance
// below is 10-100x that. Discrete decisions (the stop at transmittance 1e-4, cells at the
// density threshold, a sample exactly on a block boundary) can flip on such differences, so the
// per-pixel comparisons allow a small fraction of outliers. Sums whose order differs (gradient
// scatter with atomics vs per-vertex locks, block reductions vs chunk order) are compared with
// tolerances scaled by the magnitude of the summed terms, as the rounding error of a float sum
// is bounded by n * eps * sum |terms|, not by the (possibly cancelled) result.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>

#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/tracking_terms.h"
#include "core/mapping/map_dataset.h"
#include "core/mapping/training_set.h"
#include "core/render/render_view.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/backend_test_util.h"
#include "tests/grad_buffers.h"

namespace plx {
namespace {

using testing::CudaSkipReason;
using testing::GradBuffers;
using testing::MakeTestBackend;

constexpr int kKeyframes[] = {0, 10, 20};

float MaxAbs(const UnifiedVector<float>& v) {
  float m = 0.0f;
  for (float x : v) m = std::max(m, std::fabs(x));
  return m;
}

// Elements where |a - b| > abs_tol + rel_tol * |a|.
template <typename Floats>
int64_t CountMismatches(const Floats& a, const Floats& b, double abs_tol, double rel_tol) {
  EXPECT_EQ(a.size(), b.size());
  int64_t bad = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    if (!(std::fabs(double(a[i]) - b[i]) <= abs_tol + rel_tol * std::fabs(double(a[i])))) ++bad;
  }
  return bad;
}

class CudaParityTest : public ::testing::Test {
 protected:
  // The CUDA backend is made first: it installs the managed-memory hooks, so the dataset, map
  // and buffers allocated after it are readable by the GPU.
  static void SetUpTestSuite() {
    skip_reason_ = new std::string(CudaSkipReason());
    setup_error_ = new std::string();
    // PLX_PARITY_CPU_TWIN=1 runs the suite CPU-vs-CPU (one thread against two) where there is
    // no GPU, to check the tests themselves.
    const bool twin = std::getenv("PLX_PARITY_CPU_TWIN") != nullptr;
    if (twin) skip_reason_->clear();
    if (!skip_reason_->empty()) return;
    absl::StatusOr<std::unique_ptr<Backend>> cuda =
        twin ? absl::StatusOr<std::unique_ptr<Backend>>(MakeCpuBackend(1))
             : MakeTestBackend(BackendKind::kCuda);
    if (!cuda.ok()) {
      *setup_error_ = cuda.status().ToString();
      return;
    }
    cuda_ = cuda->release();
    cpu_ = MakeCpuBackend(2).release();
    SyntheticOptions o;
    o.width = 96;
    o.height = 72;
    o.num_frames = 21;
    absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(o);
    if (!dataset.ok()) {
      *setup_error_ = dataset.status().ToString();
      return;
    }
    dataset_ = new InMemoryDataset(std::move(*dataset));
    options_ = new MapperOptions(MapperOptionsForVoxelSize(0.03f));
    options_->max_iterations = 20;
    options_->batch_size = 4096;
    absl::StatusOr<MapDatasetResult> mapped =
        MapDataset(*dataset_, {std::begin(kKeyframes), std::end(kKeyframes)}, *options_, *cpu_);
    if (!mapped.ok()) {
      *setup_error_ = mapped.status().ToString();
      return;
    }
    map_ = mapped->map.release();
  }
  static void TearDownTestSuite() {
    delete map_;
    delete options_;
    delete dataset_;
    delete cpu_;
    delete cuda_;
    delete skip_reason_;
    delete setup_error_;
    map_ = nullptr;
    options_ = nullptr;
    dataset_ = nullptr;
    cpu_ = cuda_ = nullptr;
  }

  void SetUp() override {
    if (!skip_reason_->empty()) GTEST_SKIP() << *skip_reason_;
    ASSERT_TRUE(setup_error_->empty()) << *setup_error_;
    ASSERT_NE(map_, nullptr);
    ASSERT_GT(map_->grid.num_bricks(), 0);
  }

  static const PinholeIntrinsics& intrinsics() { return dataset_->calibration().pinhole; }
  static SE3 pose(int frame) { return *dataset_->frames()[frame].ground_truth; }

  static TrainingSet MakeTrainingSet() {
    TrainingSet set;
    for (int f : kKeyframes) {
      EXPECT_TRUE(set.AddFrame(dataset_->frames()[f], pose(f), intrinsics(), 10.0).ok());
    }
    return set;
  }

  static MappingBatchParams BatchParams() {
    MappingBatchParams p;
    p.seed = 4242;
    p.batch_size = 4096;
    p.depth_weight = options_->depth_weight;
    p.depth_huber = options_->depth_huber;
    p.depth_noise = options_->fusion.noise;
    p.sh_min_weight = options_->sh_min_weight;
    p.render = map_->render;
    return p;
  }

  static std::string* skip_reason_;
  static std::string* setup_error_;
  static Backend* cpu_;
  static Backend* cuda_;
  static InMemoryDataset* dataset_;
  static MapperOptions* options_;
  static PlenoxelMap* map_;
};
std::string* CudaParityTest::skip_reason_ = nullptr;
std::string* CudaParityTest::setup_error_ = nullptr;
Backend* CudaParityTest::cpu_ = nullptr;
Backend* CudaParityTest::cuda_ = nullptr;
InMemoryDataset* CudaParityTest::dataset_ = nullptr;
MapperOptions* CudaParityTest::options_ = nullptr;
PlenoxelMap* CudaParityTest::map_ = nullptr;

// A held-out view (frame 5), every pixel. Colour in [0, 1] to 1e-3, ranges (1-4 m) to 1 mm +
// 1e-4 relative, opacity to 1e-3; at most 0.5% of pixels may differ more (discrete flips at
// silhouettes and at the transmittance cut-off).
TEST_F(CudaParityTest, RenderPixelsMatchesCpu) {
  absl::StatusOr<RenderedPixels> rendered_a = RenderPixels(*cpu_, *map_, pose(5), intrinsics());
  absl::StatusOr<RenderedPixels> rendered_b = RenderPixels(*cuda_, *map_, pose(5), intrinsics());
  ASSERT_TRUE(rendered_a.ok()) << rendered_a.status();
  ASSERT_TRUE(rendered_b.ok()) << rendered_b.status();
  const RenderedPixels& a = *rendered_a;
  const RenderedPixels& b = *rendered_b;
  const int64_t n = static_cast<int64_t>(a.opacity.size());
  ASSERT_EQ(n, int64_t{intrinsics().width} * intrinsics().height);
  const int64_t allowed = n / 200;
  EXPECT_LE(CountMismatches(a.color, b.color, 1e-3, 0.0), 3 * allowed);
  EXPECT_LE(CountMismatches(a.depth, b.depth, 1e-3, 1e-4), allowed);
  EXPECT_LE(CountMismatches(a.median_depth, b.median_depth, 1e-3, 1e-4), allowed);
  EXPECT_LE(CountMismatches(a.opacity, b.opacity, 1e-3, 0.0), allowed);
  int rendered = 0;
  for (int64_t i = 0; i < n; ++i) rendered += a.opacity[i] >= kRenderedOpacity;
  EXPECT_GT(rendered, n / 2) << "the map should cover most of a view between keyframes";
}

// One batch of 4096 rays (drawn by the same stateless hash on both). Per-ray losses as above.
// A vertex's gradient sums contributions of many rays in a different order (GPU atomics vs CPU
// per-vertex locks): float rounding is bounded by ~k eps sum|terms| with k up to a few hundred,
// i.e. ~1e-5 of the largest gradient; we allow 1e-4 of the array's largest |gradient| plus 1e-3
// relative, and 0.1% outliers. Touched flags must agree (same rays, same samples).
TEST_F(CudaParityTest, MappingGradientsMatchCpu) {
  const TrainingSet set = MakeTrainingSet();
  const MappingBatchParams params = BatchParams();
  GradBuffers ga(map_->grid), gb(map_->grid);
  UnifiedVector<MappingRayLoss> la(params.batch_size), lb(params.batch_size);
  ASSERT_TRUE(
      cpu_->MappingForwardBackward(map_->grid.view(), ga.view(), set.rays_view(), params, la.data())
          .ok());
  ASSERT_TRUE(cuda_->MappingForwardBackward(map_->grid.view(), gb.view(), set.rays_view(), params,
                                            lb.data())
                  .ok());

  int64_t loss_bad = 0;
  for (int64_t i = 0; i < params.batch_size; ++i) {
    loss_bad += !(std::fabs(la[i].color_sq - lb[i].color_sq) <= 1e-4 + 1e-3 * la[i].color_sq);
    loss_bad += !(std::fabs(la[i].depth_abs - lb[i].depth_abs) <= 1e-3);
    loss_bad += !(std::fabs(la[i].opacity - lb[i].opacity) <= 1e-3);
  }
  EXPECT_LE(loss_bad, params.batch_size / 100);

  int64_t touched = 0, touched_differ = 0;
  for (size_t v = 0; v < ga.touched.size(); ++v) {
    touched += ga.touched[v] != 0;
    touched_differ += (ga.touched[v] != 0) != (gb.touched[v] != 0);
  }
  ASSERT_GT(touched, 1000) << "the batch should reach many vertices";
  EXPECT_LE(touched_differ, touched / 1000 + 1);
  for (size_t b = 0; b < ga.brick_touched.size(); ++b) {
    if (ga.brick_touched[b] != 0) {
      EXPECT_NE(gb.brick_touched[b], 0) << "brick " << b;
    }
  }
  const float max_density = MaxAbs(ga.density), max_sh = MaxAbs(ga.sh);
  ASSERT_GT(max_density, 0.0f);
  ASSERT_GT(max_sh, 0.0f);
  EXPECT_LE(CountMismatches(ga.density, gb.density, 1e-4 * max_density, 1e-3), touched / 1000 + 1);
  EXPECT_LE(CountMismatches(ga.sh, gb.sh, 1e-4 * max_sh, 1e-3), kShCoeffCount * touched / 1000 + 1);
}

// Tracking rays of frame 5 from a perturbed pose. Per-ray terms: residuals and Jacobians to
// 2e-3 relative (Jacobians reach ~10 and come from long chains of products), 0.5% outliers.
// The reduction alone (both backends summing the SAME terms in double) differs only by the
// order of ~16k double additions: relative 1e-9 of the largest entry is ample (eps 1e-16).
// The whole pipeline (each backend reducing its own terms) agrees to 1e-3 relative.
TEST_F(CudaParityTest, TrackingNormalEquationsMatchCpu) {
  const RgbdFrame frame = dataset_->frames()[5];  // copied into unified memory
  Vector6d offset;
  offset << 0.01, -0.008, 0.005, 0.006, -0.004, 0.008;
  TrainingFrameView view;
  view.camera = ToKernelCamera(pose(5) * SE3::Exp(offset), intrinsics());
  view.color = frame.color.data.data();
  view.depth = frame.depth.data.data();
  UnifiedVector<int32_t> pixels;
  for (int32_t p = 0; p < static_cast<int32_t>(frame.depth.data.size()) && pixels.size() < 4096;
       p += 1) {
    if (frame.depth.data[p] > 0.0f) pixels.push_back(p);
  }
  const int64_t n = static_cast<int64_t>(pixels.size());
  ASSERT_GT(n, 1000);
  TrackingParams params;
  params.render = map_->render;
  UnifiedVector<TrackingRayTerm> ta(n), tb(n);
  ASSERT_TRUE(
      cpu_->ComputeTrackingTerms(map_->grid.view(), view, pixels.data(), n, params, ta.data())
          .ok());
  ASSERT_TRUE(
      cuda_->ComputeTrackingTerms(map_->grid.view(), view, pixels.data(), n, params, tb.data())
          .ok());

  int64_t term_bad = 0, valid = 0;
  for (int64_t i = 0; i < n; ++i) {
    bool ok = true;
    for (int r = 0; r < kTrackingResiduals; ++r) {
      ok &= (ta[i].weight[r] > 0) == (tb[i].weight[r] > 0);
      if (!(ta[i].weight[r] > 0) || !(tb[i].weight[r] > 0)) continue;
      ok &= std::fabs(ta[i].weight[r] - tb[i].weight[r]) <= 1e-3f * ta[i].weight[r];
      ok &= std::fabs(ta[i].residual[r] - tb[i].residual[r]) <=
            2e-3f * std::max(1.0f, std::fabs(ta[i].residual[r]));
      for (int k = 0; k < kPoseDim; ++k) {
        ok &= std::fabs(ta[i].jacobian[r][k] - tb[i].jacobian[r][k]) <=
              2e-3f * std::max(1.0f, std::fabs(ta[i].jacobian[r][k]));
      }
    }
    valid += ta[i].weight[3] > 0;
    term_bad += !ok;
  }
  EXPECT_GT(valid, n / 2);
  EXPECT_LE(term_bad, n / 200);

  for (TrackingLoss loss : {TrackingLoss::kHuber, TrackingLoss::kL1}) {
    const float scale[2] = {1.5f, 2.0f};
    const float huber_k = 1.345f;
    TrackingSums cpu, same, own;
    ASSERT_TRUE(cpu_->ReduceTrackingTerms(ta.data(), n, loss, huber_k, scale, &cpu).ok());
    ASSERT_TRUE(cuda_->ReduceTrackingTerms(ta.data(), n, loss, huber_k, scale, &same).ok());
    ASSERT_TRUE(cuda_->ReduceTrackingTerms(tb.data(), n, loss, huber_k, scale, &own).ok());
    double h_max = 0.0, g_max = 0.0;
    for (double h : cpu.H) h_max = std::max(h_max, std::fabs(h));
    for (double g : cpu.g) g_max = std::max(g_max, std::fabs(g));
    if (loss == TrackingLoss::kHuber) {
      ASSERT_GT(h_max, 0.0);
    }
    ASSERT_GT(g_max, 0.0);
    for (int i = 0; i < kNormalUpper; ++i) {
      EXPECT_NEAR(same.H[i], cpu.H[i], 1e-9 * h_max + 1e-12) << "H[" << i << "]";
      EXPECT_NEAR(own.H[i], cpu.H[i], 1e-3 * h_max + 1e-12) << "H[" << i << "]";
    }
    for (int i = 0; i < kPoseDim; ++i) {
      EXPECT_NEAR(same.g[i], cpu.g[i], 1e-9 * g_max) << "g[" << i << "]";
      EXPECT_NEAR(own.g[i], cpu.g[i], 1e-3 * g_max) << "g[" << i << "]";
    }
    EXPECT_NEAR(same.cost, cpu.cost, 1e-9 * cpu.cost);
    EXPECT_NEAR(own.cost, cpu.cost, 1e-3 * cpu.cost);
    EXPECT_NEAR(same.residual_sq, cpu.residual_sq, 1e-9 * cpu.residual_sq);
    EXPECT_EQ(same.residual_count, cpu.residual_count);
    EXPECT_EQ(same.valid_rays, cpu.valid_rays);
    EXPECT_NEAR(own.valid_rays, cpu.valid_rays, 0.005 * n);
  }
}

// Two RMSProp steps from the same gradients on two copies of the map. The update is
// element-wise (no sums across threads): only FMA contraction and correctly rounded sqrt/div
// differ, so 1e-5 relative (plus 1e-7 absolute for values near zero) is ample. Touched flags
// must be cleared on both.
TEST_F(CudaParityTest, RmsPropStepMatchesCpu) {
  const TrainingSet set = MakeTrainingSet();
  const MappingBatchParams batch = BatchParams();
  PlenoxelMap a = map_->ShareCopy(), b = map_->ShareCopy();
  GradBuffers grads(map_->grid);
  UnifiedVector<MappingRayLoss> losses(batch.batch_size);
  ASSERT_TRUE(cpu_->MappingForwardBackward(map_->grid.view(), grads.view(), set.rays_view(),
                                           batch, losses.data())
                  .ok());
  const int64_t n = map_->grid.num_vertices();
  UnifiedVector<float> rms_da(n, 0.0f), rms_sa(n * kShCoeffCount, 0.0f);
  UnifiedVector<float> rms_db(n, 0.0f), rms_sb(n * kShCoeffCount, 0.0f);
  RmsPropParams params;
  params.lr_density = 5.0f;
  params.lr_sh = 1e-2f;
  params.sigma_threshold = map_->render.sigma_threshold;
  for (int step = 0; step < 2; ++step) {
    GradBuffers ga = grads, gb = grads;  // the step consumes (clears) them
    a.grid.MakePrivate(ga.brick_touched.data());
    b.grid.MakePrivate(gb.brick_touched.data());
    ASSERT_TRUE(cpu_->RmsPropStep(a.grid.view(), a.grid.write_view(), ga.view(),
                                  {rms_da.data(), rms_sa.data()}, params)
                    .ok());
    ASSERT_TRUE(cuda_->RmsPropStep(b.grid.view(), b.grid.write_view(), gb.view(),
                                   {rms_db.data(), rms_sb.data()}, params)
                    .ok());
    for (size_t v = 0; v < ga.touched.size(); ++v) {
      ASSERT_EQ(ga.touched[v], 0);
      ASSERT_EQ(gb.touched[v], 0) << "vertex " << v;
    }
    EXPECT_EQ(std::count(gb.density.begin(), gb.density.end(), 0.0f),
              static_cast<std::ptrdiff_t>(gb.density.size()));
  }
  EXPECT_EQ(CountMismatches(a.grid.DensityValues(), b.grid.DensityValues(), 1e-7, 1e-5), 0);
  EXPECT_EQ(CountMismatches(a.grid.ShValues(), b.grid.ShValues(), 1e-7, 1e-5), 0);
  EXPECT_EQ(CountMismatches(rms_da, rms_db, 1e-12, 1e-5), 0);
  EXPECT_EQ(CountMismatches(rms_sa, rms_sb, 1e-12, 1e-5), 0);
  EXPECT_NE(CountMismatches(map_->grid.DensityValues(), a.grid.DensityValues(), 0.0, 0.0), 0)
      << "the steps should change the map";
}

}  // namespace
}  // namespace plx

// The checks Backend makes from each kernel's argument struct (core/kernels/kernel_args.h)
// before its implementation runs: sizes, required arrays, value checks, RESOURCE_EXHAUSTED for
// an allocation failure; and the lists themselves, which the CUDA backend's residency checks
// and prefetches read too. A recording backend shows what reaches the implementation.
#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <new>
#include <set>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "core/common/unified_allocator.h"
#include "core/cpu/cpu_backend.h"
#include "core/grid/sparse_grid.h"
#include "core/kernels/backend.h"
#include "core/kernels/kernel_args.h"
#include "core/kernels/marching_cubes_table.h"
#include "tests/grad_buffers.h"

namespace plx {
namespace {

using testing::GradBuffers;

// Records each launch instead of running it; throws std::bad_alloc when told to.
class RecordingBackend final : public Backend {
 public:
  std::string name() const override { return "recording"; }
  int parallelism() const override { return 1; }

  std::vector<KernelArgs> launches;
  bool out_of_memory = false;

 protected:
  absl::Status Launch(const KernelArgs& args) override {
    if (out_of_memory) throw std::bad_alloc();
    launches.push_back(args);
    return absl::OkStatus();
  }
};

// A grid of two bricks side by side, with its index and occupancy bits.
SparseGrid TwoBrickGrid() {
  SparseGrid grid(0.05f);
  const std::vector<BrickCoord> bricks = {{0, 0, 0}, {1, 0, 0}};
  EXPECT_TRUE(grid.AllocateBricks(bricks).ok());
  return grid;
}

CameraView SmallCamera() {
  CameraView camera{};
  for (int i = 0; i < 3; ++i) camera.world_T_camera.r[4 * i] = 1.0f;
  camera.world_T_camera.t[2] = -1.0f;
  camera.fx = camera.fy = 4.0f;
  camera.cx = camera.cy = 2.0f;
  camera.width = camera.height = 4;
  return camera;
}

// Expects INVALID_ARGUMENT whose message names the kernel and the argument.
void ExpectInvalid(const absl::Status& status, const std::string& kernel,
                   const std::string& argument) {
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
  EXPECT_EQ(status.message().rfind(kernel + ": ", 0), 0u) << status;
  EXPECT_NE(status.message().find("`" + argument + "`"), std::string::npos) << status;
}

struct RenderBuffers {
  explicit RenderBuffers(int64_t n) : color(3 * n), depth(n), opacity(n), median(n) {}
  UnifiedVector<float> color, depth, opacity, median;
};

TEST(BackendChecksTest, RenderPixelsChecksItsCountOutputsAndGrid) {
  const SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  RenderBuffers out(16);
  const RenderOptions options;
  const CameraView camera = SmallCamera();
  auto render = [&](const GridView& g, int64_t count, float* color, float* opacity) {
    return backend.RenderPixels(g, camera, nullptr, count, options, color, out.depth.data(),
                                opacity, out.median.data());
  };
  ExpectInvalid(render(grid.view(), -1, out.color.data(), out.opacity.data()), "RenderPixels",
                "count");
  ExpectInvalid(render(grid.view(), 16, nullptr, out.opacity.data()), "RenderPixels", "color");
  ExpectInvalid(render(grid.view(), 16, out.color.data(), nullptr), "RenderPixels", "opacity");
  GridView no_sh = grid.view();
  no_sh.brick_sh = nullptr;
  ExpectInvalid(render(no_sh, 16, out.color.data(), out.opacity.data()), "RenderPixels",
                "grid.brick_sh");
  GridView no_index = grid.view();
  no_index.brick_slot = nullptr;
  ExpectInvalid(render(no_index, 16, out.color.data(), out.opacity.data()), "RenderPixels",
                "grid.brick_slot");
  GridView negative = grid.view();
  negative.num_bricks = -2;
  ExpectInvalid(render(negative, 16, out.color.data(), out.opacity.data()), "RenderPixels",
                "grid.num_bricks");
  EXPECT_TRUE(backend.launches.empty());

  // No pixel list means every pixel; no pixels, no outputs needed; both reach the backend.
  EXPECT_TRUE(render(grid.view(), 16, out.color.data(), out.opacity.data()).ok());
  EXPECT_TRUE(render(grid.view(), 0, nullptr, nullptr).ok());
  EXPECT_EQ(backend.launches.size(), 2u);
}

// The public methods fill their kernel's struct field by field: a swapped pair of same-typed
// arguments would reach the kernel in each other's place.
TEST(BackendChecksTest, PublicMethodsHandTheirArgumentsOnInOrder) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  RenderBuffers out(16);
  const UnifiedVector<int32_t> pixels = {0, 5, 15};
  RenderOptions options;
  options.background[1] = 0.25f;
  ASSERT_TRUE(backend
                  .RenderPixels(grid.view(), SmallCamera(), pixels.data(), 3, options,
                                out.color.data(), out.depth.data(), out.opacity.data(),
                                out.median.data())
                  .ok());
  GradBuffers grad(grid);
  UnifiedVector<float> rms_density(grid.num_vertices()), rms_sh(grid.num_vertices() * 27);
  RmsPropParams rms;
  rms.lr_sh = 0.125f;
  ASSERT_TRUE(backend
                  .RmsPropStep(grid.view(), grid.write_view(), grad.view(),
                               OptimizerStateView{rms_density.data(), rms_sh.data()}, rms)
                  .ok());
  const UnifiedVector<TrackingRayTerm> terms(5);
  TrackingSums sums;
  const float scale[2] = {2.0f, 3.0f};
  ASSERT_TRUE(
      backend.ReduceTrackingTerms(terms.data(), 5, TrackingLoss::kL1, 1.5f, scale, &sums).ok());
  UnifiedVector<float> positions(6), normals(6);
  UnifiedVector<uint8_t> colors(6), observed(2);
  const UnifiedVector<int64_t> keys = {1, 2};
  const MarchingCubesTable table{};
  IsoSurfaceParams iso;
  iso.table = &table;
  iso.iso_level = 2.0f;
  ASSERT_TRUE(backend
                  .ComputeIsoVertices(grid.view(), keys.data(), 2, iso, positions.data(),
                                      normals.data(), colors.data(), observed.data())
                  .ok());

  ASSERT_EQ(backend.launches.size(), 4u);
  const auto& render = std::get<RenderPixelsArgs>(backend.launches[0]);
  EXPECT_EQ(render.pixels, pixels.data());
  EXPECT_EQ(render.count, 3);
  EXPECT_EQ(render.options.background[1], 0.25f);
  EXPECT_EQ(render.color, out.color.data());
  EXPECT_EQ(render.depth, out.depth.data());
  EXPECT_EQ(render.opacity, out.opacity.data());
  EXPECT_EQ(render.median_depth, out.median.data());
  EXPECT_EQ(render.grid.brick_slot, grid.view().brick_slot);
  EXPECT_EQ(render.camera.width, 4);
  const auto& step = std::get<RmsPropStepArgs>(backend.launches[1]);
  EXPECT_EQ(step.grad.sh, grad.sh.data());
  EXPECT_EQ(step.state.rms_density, rms_density.data());
  EXPECT_EQ(step.state.rms_sh, rms_sh.data());
  EXPECT_EQ(step.write.cell_bits, grid.write_view().cell_bits);
  EXPECT_EQ(step.params.lr_sh, 0.125f);
  const auto& reduce = std::get<ReduceTrackingTermsArgs>(backend.launches[2]);
  EXPECT_EQ(reduce.terms, terms.data());
  EXPECT_EQ(reduce.count, 5);
  EXPECT_EQ(reduce.loss, TrackingLoss::kL1);
  EXPECT_EQ(reduce.huber_k, 1.5f);
  EXPECT_EQ(reduce.scale[0], 2.0f);
  EXPECT_EQ(reduce.scale[1], 3.0f);
  EXPECT_EQ(reduce.sums, &sums);
  const auto& vertices = std::get<ComputeIsoVerticesArgs>(backend.launches[3]);
  EXPECT_EQ(vertices.edge_keys, keys.data());
  EXPECT_EQ(vertices.positions, positions.data());
  EXPECT_EQ(vertices.normals, normals.data());
  EXPECT_EQ(vertices.colors, colors.data());
  EXPECT_EQ(vertices.observed, observed.data());
  EXPECT_EQ(vertices.params.iso_level, 2.0f);
}

TEST(BackendChecksTest, MappingNeedsItsRaysAndGradients) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  GradBuffers grad(grid);
  UnifiedVector<MappingRayLoss> losses(8);
  MappingBatchParams batch;
  batch.batch_size = 8;
  const absl::Status no_rays =
      backend.MappingForwardBackward(grid.view(), grad.view(), {}, batch, losses.data());
  EXPECT_EQ(no_rays.code(), absl::StatusCode::kFailedPrecondition) << no_rays;
  EXPECT_EQ(no_rays.message(), "MappingForwardBackward: no training rays");

  const UnifiedVector<TrainingFrameView> frames(1);
  const UnifiedVector<uint32_t> ray_frame(4, 0), ray_pixel(4, 0);
  TrainingRaysView rays{frames.data(), ray_frame.data(), ray_pixel.data(), 4, 0};
  GridGradView no_touched = grad.view();
  no_touched.touched = nullptr;
  ExpectInvalid(backend.MappingForwardBackward(grid.view(), no_touched, rays, batch, losses.data()),
                "MappingForwardBackward", "grad.touched");
  TrainingRaysView no_pixels = rays;
  no_pixels.ray_pixel = nullptr;
  ExpectInvalid(
      backend.MappingForwardBackward(grid.view(), grad.view(), no_pixels, batch, losses.data()),
      "MappingForwardBackward", "rays.ray_pixel");
  batch.batch_size = -8;
  ExpectInvalid(
      backend.MappingForwardBackward(grid.view(), grad.view(), rays, batch, losses.data()),
      "MappingForwardBackward", "params.batch_size");
  EXPECT_TRUE(backend.launches.empty());
  batch.batch_size = 8;
  EXPECT_TRUE(
      backend.MappingForwardBackward(grid.view(), grad.view(), rays, batch, losses.data()).ok());
  EXPECT_EQ(backend.launches.size(), 1u);
}

TEST(BackendChecksTest, FuseDepthChecksEveryFramesImagesAndTheVertexRange) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  const CameraView camera = SmallCamera();
  const UnifiedVector<float> color(48), depth(16);
  UnifiedVector<TrainingFrameView> frames(2, TrainingFrameView{camera, color.data(), depth.data()});
  const FusionParams params;
  auto fuse = [&](int64_t first, int64_t count) {
    return backend.FuseDepth(grid.view(), grid.write_view(), first, count, frames.data(), 2,
                             params);
  };
  EXPECT_TRUE(fuse(0, grid.num_vertices()).ok());
  const absl::Status outside = fuse(512, 513);
  ExpectInvalid(outside, "FuseDepth", "vertex_count");
  EXPECT_NE(outside.message().find("outside the grid's 1024 vertices"), std::string::npos)
      << outside;
  frames[1].depth = nullptr;
  ExpectInvalid(fuse(0, 1), "FuseDepth", "frames[].depth");
  EXPECT_EQ(backend.launches.size(), 1u);
}

TEST(BackendChecksTest, NegativeSizesNameTheirArgument) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  ExpectInvalid(backend.FuseDepth(grid.view(), grid.write_view(), 0, -1, nullptr, 0, {}),
                "FuseDepth", "vertex_count");
  const UnifiedVector<int64_t> blocks = {0};
  ExpectInvalid(backend.RefreshOccupancy(grid.view(), grid.write_view(), blocks.data(), -1, 0.1f),
                "RefreshOccupancy", "count");
  GradBuffers grad(grid);
  ExpectInvalid(backend.AddTvGradient(grid.view(), grad.view(), 0, -5, 1.0f, 1.0f), "AddTvGradient",
                "vertex_count");
  ExpectInvalid(backend.AddTvGradient(grid.view(), grad.view(), -1, 5, 1.0f, 1.0f), "AddTvGradient",
                "first_vertex");
  EXPECT_TRUE(backend.launches.empty());
}

TEST(BackendChecksTest, OccupancyTrackingAndMeshArraysAreRequiredWhenUsed) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  const UnifiedVector<int64_t> blocks = {0};
  GridWriteView no_bits = grid.write_view();
  no_bits.cell_bits = nullptr;
  ExpectInvalid(backend.RefreshOccupancy(grid.view(), no_bits, blocks.data(), 1, 0.1f),
                "RefreshOccupancy", "write.cell_bits");
  EXPECT_TRUE(backend.RefreshOccupancy(grid.view(), no_bits, nullptr, 0, 0.1f).ok());

  const UnifiedVector<TrackingRayTerm> terms(3);
  const float scale[2] = {1.0f, 1.0f};
  ExpectInvalid(
      backend.ReduceTrackingTerms(terms.data(), 3, TrackingLoss::kHuber, 1.0f, scale, nullptr),
      "ReduceTrackingTerms", "sums");
  const UnifiedVector<float> color(48);
  const TrainingFrameView no_depth{SmallCamera(), color.data(), nullptr};
  const UnifiedVector<int32_t> pixels = {1, 2, 3};
  UnifiedVector<TrackingRayTerm> out(3);
  ExpectInvalid(
      backend.ComputeTrackingTerms(grid.view(), no_depth, pixels.data(), 3, {}, out.data()),
      "ComputeTrackingTerms", "frame.depth");

  const MarchingCubesTable table{};
  IsoSurfaceParams iso;
  ExpectInvalid(backend.CountIsoTriangles(grid.view(), 0, 0, iso, nullptr), "CountIsoTriangles",
                "params.table");
  iso.table = &table;
  const UnifiedVector<int64_t> first(4, 0);
  ExpectInvalid(backend.EmitIsoTriangles(grid.view(), 0, 4, iso, first.data(), nullptr),
                "EmitIsoTriangles", "edge_keys");
  // A brick list (a region's bricks): its slots are required when it counts any, and the cells
  // asked for lie in it, not in the grid.
  UnifiedVector<uint8_t> counts(2 * kBrickVertices);
  ExpectInvalid(backend.CountIsoTriangles(grid.view(), 0, 4, iso, counts.data(),
                                          IsoBrickList{nullptr, 1}),
                "CountIsoTriangles", "bricks.slots");
  const UnifiedVector<int32_t> slots = {1};
  ExpectInvalid(backend.CountIsoTriangles(grid.view(), 0, 2 * kBrickVertices, iso, counts.data(),
                                          IsoBrickList{slots.data(), 1}),
                "CountIsoTriangles", "first_vertex");
  iso.iso_level = -1.0f;
  const absl::Status level = backend.CountIsoTriangles(grid.view(), 0, 0, iso, nullptr);
  EXPECT_EQ(level.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(level.message().rfind("CountIsoTriangles: `params.iso_level` must be", 0), 0u) << level;
  EXPECT_EQ(backend.launches.size(), 1u);  // the occupancy refresh of no blocks
}

TEST(BackendChecksTest, CallsWithNothingToDoDoNotReachTheBackend) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  SparseGrid empty(0.05f);
  EXPECT_TRUE(backend.AddTvGradient(empty.view(), {}, 0, 10, 1.0f, 1.0f).ok());
  const MarchingCubesTable table{};
  IsoSurfaceParams iso;
  iso.table = &table;
  EXPECT_TRUE(backend.CountIsoTriangles(grid.view(), 0, 0, iso, nullptr).ok());
  EXPECT_TRUE(backend.EmitIsoTriangles(grid.view(), 0, 0, iso, nullptr, nullptr).ok());
  EXPECT_TRUE(
      backend.ComputeIsoVertices(grid.view(), nullptr, 0, iso, nullptr, nullptr, nullptr, nullptr)
          .ok());
  EXPECT_TRUE(
      backend.ObserveSurface(grid.view(), IsoBrickList{}, nullptr, 0, FusionParams{}, nullptr)
          .ok());
  EXPECT_TRUE(backend.launches.empty());
}

TEST(BackendChecksTest, AnAllocationFailureIsResourceExhaustedNamingTheKernel) {
  SparseGrid grid = TwoBrickGrid();
  RecordingBackend backend;
  backend.out_of_memory = true;
  GridView target = grid.view();
  const absl::Status status = backend.ResampleGrid(target, grid.write_view(), target);
  EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(status.message(), "ResampleGrid: out of memory");
}

// The same checks in front of the real CPU backend, and its results for a valid call.
TEST(BackendChecksTest, TheCpuBackendChecksBeforeItRuns) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  const SparseGrid grid = TwoBrickGrid();
  RenderBuffers out(16);
  out.opacity.assign(16, -1.0f);
  const RenderOptions options;
  ExpectInvalid(
      backend->RenderPixels(grid.view(), SmallCamera(), nullptr, 16, options, out.color.data(),
                            nullptr, out.opacity.data(), out.median.data()),
      "RenderPixels", "depth");
  EXPECT_EQ(out.opacity[0], -1.0f);  // nothing ran
  ASSERT_TRUE(backend
                  ->RenderPixels(grid.view(), SmallCamera(), nullptr, 16, options, out.color.data(),
                                 out.depth.data(), out.opacity.data(), out.median.data())
                  .ok());
  for (float o : out.opacity) EXPECT_EQ(o, 0.0f);  // an empty (zero-density) grid
}

// The lists the checks and the CUDA backend read: each argument once per kernel, and the
// prefetched arrays with the sizes the CUDA backend moves (docs/GPU.md: the grid's index,
// gradients and optimiser state).
template <size_t... I>
std::vector<std::pair<std::string, std::vector<std::string>>> AllKernelLabels(
    std::index_sequence<I...>) {
  std::vector<std::pair<std::string, std::vector<std::string>>> kernels;
  auto add = [&](const auto& args) {
    std::vector<std::string> labels;
    args.ForEachArgument(
        [&](const auto& item) { labels.push_back(ArgumentLabel(item.group, item.name)); });
    kernels.emplace_back(std::decay_t<decltype(args)>::kName, std::move(labels));
  };
  (add(std::variant_alternative_t<I, KernelArgs>{}), ...);
  return kernels;
}

TEST(KernelArgsTest, EveryKernelListsEachArgumentOnce) {
  const auto kernels = AllKernelLabels(std::make_index_sequence<std::variant_size_v<KernelArgs>>());
  ASSERT_EQ(kernels.size(), 13u);
  std::set<std::string> names;
  for (const auto& [kernel, labels] : kernels) {
    EXPECT_TRUE(names.insert(kernel).second) << kernel;
    EXPECT_FALSE(labels.empty()) << kernel;
    const std::set<std::string> unique(labels.begin(), labels.end());
    EXPECT_EQ(unique.size(), labels.size()) << kernel;
  }
}

TEST(KernelArgsTest, RmsPropStepPrefetchesTheIndexGradientsAndState) {
  SparseGrid grid = TwoBrickGrid();
  GradBuffers grad(grid);
  const size_t n = static_cast<size_t>(grid.num_vertices());
  UnifiedVector<float> rms_density(n), rms_sh(n * kShCoeffCount);
  RmsPropStepArgs args{.grid = grid.view(),
                       .write = grid.write_view(),
                       .grad = grad.view(),
                       .state = {rms_density.data(), rms_sh.data()},
                       .params = {}};
  const GridView view = grid.view();
  const size_t index = size_t{4} * view.dims[0] * view.dims[1] * view.dims[2];
  std::vector<std::pair<std::string, size_t>> prefetched;
  int written = 0;
  ForEachBuffer(args, [&](const KernelBuffer& b) {
    if (b.prefetch) prefetched.emplace_back(ArgumentLabel(b.group, b.name), b.bytes());
    if (b.access != BufferAccess::kRead) ++written;
  });
  const std::vector<std::pair<std::string, size_t>> expected = {{"grid.brick_slot", index},
                                                                {"grad.density", 4 * n},
                                                                {"grad.sh", 4 * 27 * n},
                                                                {"state.rms_density", 4 * n},
                                                                {"state.rms_sh", 4 * 27 * n}};
  EXPECT_EQ(prefetched, expected);
  // write.{brick_density, brick_sh, cell_bits}, grad's four arrays, state's two.
  EXPECT_EQ(written, 9);
}

}  // namespace
}  // namespace plx

// RenderView works through a view in row tiles and asks its caller between tiles whether to
// go on: the tiled view is the same, bit for bit, as one pass over every pixel, and a caller
// that gives up stops the render within a tile (a daemon's worker is not held for the rest).
#include "core/render/render_view.h"

#include <unistd.h>

#include <cstring>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/kernels/refresh_occupancy.h"
#include "gmock/gmock.h"
#include "tests/grid_fill.h"

namespace plx {
namespace {

// A block of random density and colour in front of a camera at the origin.
std::unique_ptr<PlenoxelMap> MakeMap(Backend& backend) {
  auto map = std::make_unique<PlenoxelMap>(0.05f);
  std::vector<BrickCoord> bricks;
  for (int x = -2; x < 2; ++x) {
    for (int y = -2; y < 2; ++y) bricks.push_back({x, y, 3});
  }
  EXPECT_TRUE(map->grid.AllocateBricks(bricks).ok());
  std::mt19937 rng(7);
  testing::FillDensity(map->grid, [&] { return static_cast<float>(rng() % 1000) * 0.02f; });
  testing::FillSh(map->grid, [&] { return static_cast<float>(rng() % 1000) * 0.001f - 0.5f; });
  EXPECT_TRUE(RefreshOccupancyIfStale(backend, *map).ok());
  return map;
}

TEST(RenderViewTest, TilesGiveTheSameViewAsOnePass) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const std::unique_ptr<PlenoxelMap> map = MakeMap(*backend);
  const PinholeIntrinsics k{60, 60, 40, 30, 80, 61};
  RenderViewOptions one_pass;
  one_pass.tile_pixels = int64_t{1} << 30;
  RenderViewOptions tiles;
  tiles.tile_pixels = 7 * 80 + 13;  // 7 rows per tile, the last one short
  const absl::StatusOr<RenderedView> a = RenderView(*backend, *map, SE3(), k, one_pass);
  const absl::StatusOr<RenderedView> b = RenderView(*backend, *map, SE3(), k, tiles);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  ASSERT_EQ(a->color.data.size(), b->color.data.size());
  EXPECT_EQ(0, std::memcmp(a->color.data.data(), b->color.data.data(),
                           a->color.data.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(a->z_depth.data.data(), b->z_depth.data.data(),
                           a->z_depth.data.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(a->opacity.data.data(), b->opacity.data.data(),
                           a->opacity.data.size() * sizeof(float)));
  double opacity = 0.0;
  for (float o : b->opacity.data) opacity += o;
  EXPECT_GT(opacity, 100.0) << "the test map should be visible";
}

TEST(RenderViewTest, ACancelledRenderStopsBetweenTiles) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const std::unique_ptr<PlenoxelMap> map = MakeMap(*backend);
  const PinholeIntrinsics k{60, 60, 40, 30, 80, 60};
  RenderViewOptions options;
  options.tile_pixels = 80 * 10;  // 6 tiles
  int asked = 0;
  options.cancelled = [&] { return ++asked > 2; };  // the caller gives up after 2 tiles
  const absl::StatusOr<RenderedView> view = RenderView(*backend, *map, SE3(), k, options);
  EXPECT_EQ(view.status().code(), absl::StatusCode::kCancelled) << view.status();
  EXPECT_THAT(view.status().message(), ::testing::HasSubstr("after 20 of 60 rows"));
  EXPECT_EQ(asked, 3);
}

// This process's resident memory (/proc/self/statm): what a render has touched so far. The
// images of a large view are fresh mappings of the allocator, so they count only once written.
int64_t ResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  int64_t size = 0, resident = 0;
  statm >> size >> resident;
  return resident * sysconf(_SC_PAGESIZE);
}

// A 4096 x 3072 view's three images are 252 MB. They used to be allocated and zeroed before the
// first cancellation check (for 8192^2, 1.3 GB: seconds of a worker after its caller gave up).
// What a render has touched when it is asked is the work it did, without timing anything: far
// less than the images when it is asked before its first tile, and only about a tile (2^18
// pixels, ~12 MB of buffers and image rows) when asked after it.
constexpr PinholeIntrinsics kLargeView{3000, 3000, 2048, 1536, 4096, 3072};
constexpr int64_t kLargeViewImageBytes = int64_t{4096} * 3072 * 5 * sizeof(float);
constexpr int64_t kAboutATile = 48 << 20;

TEST(RenderViewTest, ARenderCancelledBeforeItStartsTouchesNoImage) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const PlenoxelMap empty(0.05f);
  RenderViewOptions options;
  const int64_t before = ResidentBytes();
  int64_t touched = 0;
  bool asked = false;
  options.cancelled = [&] {
    asked = true;
    touched = ResidentBytes() - before;
    return true;
  };
  const absl::StatusOr<RenderedView> view = RenderView(*backend, empty, SE3(), kLargeView, options);
  EXPECT_EQ(view.status().code(), absl::StatusCode::kCancelled) << view.status();
  EXPECT_THAT(view.status().message(), ::testing::HasSubstr("after 0 of 3072 rows"));
  ASSERT_TRUE(asked);
  EXPECT_LT(touched, kAboutATile) << "the images (" << kLargeViewImageBytes
                                  << " bytes) were filled before the first question";
}

TEST(RenderViewTest, ALargeRenderCancelledAfterATileTouchedOnlyThatTile) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const PlenoxelMap empty(0.05f);
  RenderViewOptions options;
  const int64_t before = ResidentBytes();
  int64_t touched = 0;
  int asked = 0;
  options.cancelled = [&] {
    if (++asked < 2) return false;
    touched = ResidentBytes() - before;
    return true;
  };
  const absl::StatusOr<RenderedView> view = RenderView(*backend, empty, SE3(), kLargeView, options);
  EXPECT_EQ(view.status().code(), absl::StatusCode::kCancelled) << view.status();
  EXPECT_THAT(view.status().message(), ::testing::HasSubstr("after 64 of 3072 rows"));
  ASSERT_EQ(asked, 2);
  EXPECT_LT(touched, kAboutATile) << "of " << kLargeViewImageBytes << " bytes of images";
}

TEST(RenderViewTest, ThePixelLimitNamesTheSizeAndTheLimit) {
  EXPECT_TRUE(CheckRenderPixels(PinholeIntrinsics{500, 500, 320, 240, 3840, 2160},
                                int64_t{3840} * 2160)
                  .ok());
  const absl::Status s =
      CheckRenderPixels(PinholeIntrinsics{500, 500, 320, 240, 8192, 8192}, int64_t{3840} * 2160);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(s.message(),
            "8192 x 8192 = 67108864 pixels, over the limit of 8294400 pixels per render");
}

}  // namespace
}  // namespace plx

#include "core/tracking/pixel_selection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace plx {
namespace {

constexpr int kW = 64, kH = 48;
constexpr int kStepColumn = 40;  // depth steps from 2 m to 3 m here

// Left half a checkerboard of 4-pixel squares, right half flat grey; depth 2 m left of
// kStepColumn and 3 m from it on; no depth in the 4x4 block at (10, 10) (a hole).
RgbdFrame TestFrame(bool textured = true) {
  RgbdFrame f;
  f.color = ColorImage(kW, kH, 3, 0.5f);
  f.depth = DepthImage(kW, kH, 1, 0.0f);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      if (textured && u < kW / 2) {
        const float c = ((u / 4 + v / 4) % 2) ? 0.9f : 0.1f;
        for (int ch = 0; ch < 3; ++ch) f.color.pixel(u, v)[ch] = c;
      }
      const bool hole = u >= 10 && u < 14 && v >= 10 && v < 14;
      *f.depth.pixel(u, v) = hole ? 0.0f : (u < kStepColumn ? 2.0f : 3.0f);
    }
  }
  return f;
}

UnifiedVector<int32_t> Select(const RgbdFrame& f, PixelSampling sampling, int count,
                              uint32_t seed = 1) {
  PixelSelectionOptions options;
  options.sampling = sampling;
  std::mt19937 rng(seed);
  PixelSelectionScratch scratch;
  UnifiedVector<int32_t> out;
  SelectTrackingPixels(f, options, count, &rng, &scratch, &out);
  return out;
}

TEST(PixelSelectionTest, InformativeSkipsMissingDepthDepthEdgesAndTheBorder) {
  const UnifiedVector<int32_t> pixels = Select(TestFrame(), PixelSampling::kInformative, 2000);
  ASSERT_EQ(pixels.size(), 2000u);
  for (int32_t p : pixels) {
    const int u = p % kW, v = p / kW;
    EXPECT_GT(*TestFrame().depth.pixel(u, v), 0.0f) << u << "," << v;
    EXPECT_TRUE(u > 0 && u < kW - 1 && v > 0 && v < kH - 1) << "border " << u << "," << v;
    EXPECT_FALSE(u == kStepColumn - 1 || u == kStepColumn) << "depth edge at " << u;
    // Next to the hole is an edge too (a missing 4-neighbour).
    const bool beside_hole = (u >= 10 && u < 14 && (v == 9 || v == 14)) ||
                             (v >= 10 && v < 14 && (u == 9 || u == 14));
    EXPECT_FALSE(beside_hole) << "beside the hole " << u << "," << v;
  }
}

TEST(PixelSelectionTest, TextureDrawsMoreRaysButFlatSurfacesKeepTheirShare) {
  const UnifiedVector<int32_t> pixels = Select(TestFrame(), PixelSampling::kInformative, 4000);
  int textured = 0;
  for (int32_t p : pixels) textured += p % kW < kW / 2;
  const double share = textured / 4000.0;
  // The textured half has ~half the candidates; its edge pixels weigh up to 5x the mean, flat
  // pixels 1x: it must draw clearly more than half, and the flat half no less than a fifth
  // (its floor weight is the mean gradient).
  EXPECT_GT(share, 0.6);
  EXPECT_LT(share, 0.8);
  // Uniform draws ignore texture: about half (the hole and the border aside).
  const UnifiedVector<int32_t> uniform = Select(TestFrame(), PixelSampling::kUniform, 4000);
  int uniform_textured = 0;
  for (int32_t p : uniform) uniform_textured += p % kW < kW / 2;
  EXPECT_NEAR(uniform_textured / 4000.0, 0.5, 0.05);
}

TEST(PixelSelectionTest, SpreadsEvenlyAndEveryPrefixCoversTheImage) {
  // Textureless: equal weights, so systematic sampling puts in each band of rows its share of
  // the candidates within one ray (independent draws would be off by ~sqrt(n)).
  const RgbdFrame flat = TestFrame(/*textured=*/false);
  const int count = 460;
  const UnifiedVector<int32_t> pixels = Select(flat, PixelSampling::kInformative, count);
  ASSERT_EQ(pixels.size(), static_cast<size_t>(count));
  std::vector<int> per_row(kH, 0);
  for (int32_t p : pixels) ++per_row[p / kW];
  // Candidates per interior row: 62 interior columns minus the two edge columns; the hole's
  // rows lose its 4 columns and the 2 beside it, the rows above and below it 4.
  int total_candidates = 0;
  std::vector<int> candidates(kH, 0);
  for (int v = 1; v < kH - 1; ++v) {
    candidates[v] = 60 - (v >= 10 && v < 14 ? 6 : (v == 9 || v == 14 ? 4 : 0));
    total_candidates += candidates[v];
  }
  for (int v = 1; v < kH - 1; v += 8) {
    int drawn = 0;
    double expected = 0.0;
    for (int r = v; r < std::min(v + 8, kH - 1); ++r) {
      drawn += per_row[r];
      expected += static_cast<double>(count) * candidates[r] / total_candidates;
    }
    // A contiguous stretch of the cumulative weights holds floor or ceil of its share.
    EXPECT_LT(std::abs(drawn - expected), 1.0) << "rows from " << v;
  }
  // The coarse level's prefix (a quarter) reaches every quadrant.
  std::set<int> quadrants;
  for (int i = 0; i < count / 4; ++i) {
    const int u = pixels[i] % kW, v = pixels[i] / kW;
    quadrants.insert((u < kW / 2 ? 0 : 1) + (v < kH / 2 ? 0 : 2));
  }
  EXPECT_EQ(quadrants.size(), 4u);
}

TEST(PixelSelectionTest, DeterministicForASeedAndEmptyWithoutDepth) {
  EXPECT_EQ(Select(TestFrame(), PixelSampling::kInformative, 300, 7),
            Select(TestFrame(), PixelSampling::kInformative, 300, 7));
  EXPECT_NE(Select(TestFrame(), PixelSampling::kInformative, 300, 7),
            Select(TestFrame(), PixelSampling::kInformative, 300, 8));
  RgbdFrame no_depth = TestFrame();
  for (float& d : no_depth.depth.data) d = 0.0f;
  EXPECT_TRUE(Select(no_depth, PixelSampling::kInformative, 300).empty());
  EXPECT_TRUE(Select(no_depth, PixelSampling::kUniform, 300).empty());
  // Depth only on isolated pixels (all of them edges): still rays, drawn from those pixels.
  RgbdFrame sparse = no_depth;
  *sparse.depth.pixel(20, 20) = 1.5f;
  *sparse.depth.pixel(40, 30) = 1.5f;
  const UnifiedVector<int32_t> pixels = Select(sparse, PixelSampling::kInformative, 50);
  ASSERT_EQ(pixels.size(), 50u);
  for (int32_t p : pixels) EXPECT_TRUE(p == 20 * kW + 20 || p == 30 * kW + 40) << p;
}

}  // namespace
}  // namespace plx

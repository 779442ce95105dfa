#include "core/tracking/pixel_selection.h"

#include <algorithm>
#include <cmath>

namespace plx {
namespace {

bool ValidDepth(float d, float max_depth) { return d > 0.0f && d <= max_depth; }

float Luminance(const float* rgb) { return 0.299f * rgb[0] + 0.587f * rgb[1] + 0.114f * rgb[2]; }

// Uniform draws (with repetition, as the tracker has always drawn) over the pixels with valid
// depth, listed into `candidates`; none when there are none.
void DrawUniform(const DepthImage& depth, float max_depth, int count, std::mt19937* rng,
                 std::vector<int32_t>* candidates, UnifiedVector<int32_t>* out) {
  candidates->clear();
  for (int32_t p = 0; p < static_cast<int32_t>(depth.data.size()); ++p) {
    if (ValidDepth(depth.data[p], max_depth)) candidates->push_back(p);
  }
  if (candidates->empty()) return;
  std::uniform_int_distribution<size_t> pick(0, candidates->size() - 1);
  out->resize(static_cast<size_t>(count));
  for (int32_t& p : *out) p = (*candidates)[pick(*rng)];
}

}  // namespace

void SelectTrackingPixels(const RgbdFrame& frame, const PixelSelectionOptions& options, int count,
                          std::mt19937* rng, PixelSelectionScratch* scratch,
                          UnifiedVector<int32_t>* out) {
  out->clear();
  std::vector<int32_t>& candidates = scratch->candidates;
  candidates.clear();
  const int w = frame.depth.width, h = frame.depth.height;
  const float* depth = frame.depth.data.data();
  if (count <= 0 || w <= 0 || h <= 0) return;
  if (options.sampling == PixelSampling::kUniform || frame.color.width != w ||
      frame.color.height != h || frame.color.channels != 3) {
    DrawUniform(frame.depth, options.max_depth, count, rng, &candidates, out);
    return;
  }

  // Interior pixels with valid depth off depth edges, and their colour gradient magnitude
  // (central differences of luminance), kept in `cumulative` for now.
  std::vector<double>& weight = scratch->cumulative;
  weight.clear();
  const float* color = frame.color.data.data();
  double gradient_sum = 0.0;
  for (int v = 1; v + 1 < h; ++v) {
    for (int u = 1; u + 1 < w; ++u) {
      const int32_t p = v * w + u;
      const float d = depth[p];
      if (!ValidDepth(d, options.max_depth)) continue;
      const float tolerance = options.depth_edge_fraction * d;
      bool edge = false;
      for (const int32_t q : {p - 1, p + 1, p - w, p + w}) {
        edge = edge || !ValidDepth(depth[q], options.max_depth) ||
               std::fabs(depth[q] - d) > tolerance;
      }
      if (edge) continue;
      const float gx = Luminance(color + 3 * (p + 1)) - Luminance(color + 3 * (p - 1));
      const float gy = Luminance(color + 3 * (p + w)) - Luminance(color + 3 * (p - w));
      const double g = 0.5 * std::sqrt(gx * gx + gy * gy);
      candidates.push_back(p);
      weight.push_back(g);
      gradient_sum += g;
    }
  }
  if (candidates.empty()) {
    // Depth only on edges or at the border: better than no rays at all.
    DrawUniform(frame.depth, options.max_depth, count, rng, &candidates, out);
    return;
  }
  // A textureless view weighs every pixel alike: coverage is all that counts there.
  const double mean =
      gradient_sum > 0.0 ? gradient_sum / static_cast<double>(candidates.size()) : 1.0;
  const double cap = options.gradient_cap * mean;
  double total = 0.0;
  for (double& c : weight) {
    total += mean + std::min(c, cap);
    c = total;
  }
  // Systematic sampling along the row-major cumulative weights: one draw per equal slice of the
  // total, so the rays spread over the image in proportion to weight without the clumps of
  // independent draws; then shuffled so that every prefix is spread too.
  const double slice = total / count;
  std::uniform_real_distribution<double> offset(0.0, slice);
  double next = offset(*rng);
  size_t i = 0;
  out->reserve(static_cast<size_t>(count));
  for (int n = 0; n < count; ++n, next += slice) {
    while (i + 1 < weight.size() && weight[i] <= next) ++i;
    out->push_back(candidates[i]);
  }
  std::shuffle(out->begin(), out->end(), *rng);
}

}  // namespace plx

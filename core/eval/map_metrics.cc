#include "core/eval/map_metrics.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/render/render_view.h"

namespace plx {

std::vector<int> KeyframeIndices(int num_frames, int every) {
  std::vector<int> out;
  for (int i = 0; i < num_frames; i += std::max(1, every)) out.push_back(i);
  return out;
}

std::vector<int> HeldOutFrames(int num_frames, int every, int max_frames) {
  std::vector<int> all;
  every = std::max(1, every);
  for (int i = 0; i < num_frames; ++i) {
    if (every == 1 || i % every == every / 2) all.push_back(i);
  }
  if (max_frames <= 0 || static_cast<int>(all.size()) <= max_frames) return all;
  std::vector<int> picked;
  for (int j = 0; j < max_frames; ++j) {
    picked.push_back(all[static_cast<size_t>(j) * all.size() / max_frames]);
  }
  return picked;
}

absl::StatusOr<MapEvalResult> EvaluateMap(Backend& backend, const PlenoxelMap& map,
                                          const RgbdDataset& dataset,
                                          const std::vector<int>& frame_indices,
                                          const MapEvalOptions& options) {
  if (frame_indices.empty()) return absl::InvalidArgumentError("no frames to evaluate");
  const PinholeIntrinsics& k = dataset.calibration().pinhole;
  MapEvalResult result;
  std::vector<float> depth_errors;
  double psnr_sum = 0.0;
  int64_t covered = 0;
  for (int index : frame_indices) {
    if (index < 0 || index >= dataset.size()) {
      return absl::OutOfRangeError(absl::StrCat("frame ", index, " is not in the dataset"));
    }
    const std::optional<SE3> pose = dataset.ground_truth(index);
    if (!pose) {
      return absl::FailedPreconditionError(
          absl::StrCat("frame ", index, " has no ground-truth pose to render from"));
    }
    PLX_ASSIGN_OR_RETURN(RgbdFrame frame, dataset.LoadFrame(index));
    std::vector<int32_t> valid;
    for (int32_t p = 0; p < static_cast<int32_t>(frame.depth.data.size()); ++p) {
      const float d = frame.depth.data[p];
      if (d > 0.0f && d <= options.max_depth) valid.push_back(p);
    }
    if (valid.empty()) continue;
    std::mt19937 rng(options.seed + static_cast<uint32_t>(index));
    const size_t n = options.pixels_per_frame > 0
                         ? std::min<size_t>(valid.size(), options.pixels_per_frame)
                         : valid.size();
    for (size_t i = 0; n < valid.size() && i < n; ++i) {
      std::uniform_int_distribution<size_t> pick(i, valid.size() - 1);
      std::swap(valid[i], valid[pick(rng)]);
    }
    valid.resize(n);
    PLX_ASSIGN_OR_RETURN(const RenderedPixels px, RenderPixels(backend, map, *pose, k, valid));
    double sq = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const int32_t p = valid[i];
      for (int c = 0; c < 3; ++c) {
        const double e = std::clamp(px.color[3 * i + c], 0.0f, 1.0f) - frame.color.data[3 * p + c];
        sq += e * e;
      }
      const float rendered = px.RenderedRange(static_cast<int64_t>(i));
      if (rendered > 0.0f) {
        const int u = p % k.width, v = p / k.width;
        const double x = (u + 0.5 - k.cx) / k.fx, y = (v + 0.5 - k.cy) / k.fy;
        const double measured = frame.depth.data[p] * std::sqrt(x * x + y * y + 1.0);
        depth_errors.push_back(static_cast<float>(std::abs(rendered - measured)));
        ++covered;
      }
    }
    const double mse = sq / (3.0 * n);
    psnr_sum += -10.0 * std::log10(std::max(mse, 1e-12));
    result.pixels += static_cast<int64_t>(n);
    ++result.frames;
  }
  if (result.frames == 0) {
    return absl::FailedPreconditionError("no evaluated frame has valid depth");
  }
  result.psnr = psnr_sum / result.frames;
  result.coverage = static_cast<double>(covered) / static_cast<double>(result.pixels);
  if (!depth_errors.empty()) {
    double sum = 0.0;
    for (float e : depth_errors) sum += e;
    result.depth_l1_m = sum / depth_errors.size();
    std::nth_element(depth_errors.begin(), depth_errors.begin() + depth_errors.size() / 2,
                     depth_errors.end());
    result.depth_l1_median_m = depth_errors[depth_errors.size() / 2];
  }
  return result;
}

}  // namespace plx

#include "core/odometry/odometry_pyramid.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_format.h"
#include "core/geometry/luma.h"

namespace plx {
namespace {

// Neighbouring depths further apart than this fraction are an edge, not a slope: a depth
// gradient across them would pull the pose towards whichever side the point lands on.
constexpr float kDepthEdgeFraction = 0.05f;

OdometryLevel HalfLevel(const OdometryLevel& fine, float tolerance) {
  OdometryLevel coarse;
  coarse.width = fine.width / 2;
  coarse.height = fine.height / 2;
  coarse.fx = fine.fx / 2;
  coarse.fy = fine.fy / 2;
  coarse.cx = fine.cx / 2;
  coarse.cy = fine.cy / 2;
  const size_t n = static_cast<size_t>(coarse.width) * coarse.height;
  coarse.intensity.resize(n);
  coarse.depth.resize(n);
  for (int v = 0; v < coarse.height; ++v) {
    for (int u = 0; u < coarse.width; ++u) {
      const int i00 = (2 * v) * fine.width + 2 * u;
      const int block[4] = {i00, i00 + 1, i00 + fine.width, i00 + fine.width + 1};
      float intensity = 0.0f;
      float nearest = 0.0f;
      for (int i : block) {
        intensity += fine.intensity[i];
        const float d = fine.depth[i];
        if (d > 0.0f && (nearest == 0.0f || d < nearest)) nearest = d;
      }
      float sum = 0.0f;
      int count = 0;
      for (int i : block) {
        const float d = fine.depth[i];
        if (d > 0.0f && d <= nearest * (1.0f + tolerance)) {
          sum += d;
          ++count;
        }
      }
      const size_t out = static_cast<size_t>(v) * coarse.width + u;
      coarse.intensity[out] = 0.25f * intensity;
      coarse.depth[out] = count > 0 ? sum / count : 0.0f;
    }
  }
  return coarse;
}

void ComputeGradients(OdometryLevel* level) {
  const int w = level->width, h = level->height;
  const size_t n = static_cast<size_t>(w) * h;
  level->intensity_du.assign(n, 0.0f);
  level->intensity_dv.assign(n, 0.0f);
  level->depth_du.assign(n, 0.0f);
  level->depth_dv.assign(n, 0.0f);
  level->depth_smooth.assign(n, 0);
  const std::vector<float>& I = level->intensity;
  const std::vector<float>& D = level->depth;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      const int l = u > 0 ? i - 1 : i, r = u + 1 < w ? i + 1 : i;
      const int t = v > 0 ? i - w : i, b = v + 1 < h ? i + w : i;
      level->intensity_du[i] = (I[r] - I[l]) / static_cast<float>(std::max(1, r - l));
      level->intensity_dv[i] = (I[b] - I[t]) / static_cast<float>(std::max(1, (b - t) / w));
      if (u == 0 || v == 0 || u + 1 == w || v + 1 == h) continue;
      const float d = D[i];
      if (d <= 0.0f) continue;
      bool smooth = true;
      for (int j : {l, r, t, b}) {
        smooth = smooth && D[j] > 0.0f && std::fabs(D[j] - d) <= kDepthEdgeFraction * d;
      }
      if (!smooth) continue;
      level->depth_smooth[i] = 1;
      level->depth_du[i] = 0.5f * (D[r] - D[l]);
      level->depth_dv[i] = 0.5f * (D[b] - D[t]);
    }
  }
}

}  // namespace

absl::Status ValidateOdometryPyramidOptions(const OdometryPyramidOptions& o) {
  if (o.min_width < 8) return absl::InvalidArgumentError("odometry pyramid: min_width < 8");
  if (o.max_width < o.min_width) {
    return absl::InvalidArgumentError("odometry pyramid: max_width < min_width");
  }
  if (!(o.min_depth >= 0.0f) || !(o.max_depth > o.min_depth) || !std::isfinite(o.max_depth)) {
    return absl::InvalidArgumentError("odometry pyramid: need 0 <= min_depth < max_depth");
  }
  if (!(o.depth_block_tolerance >= 0.0f && o.depth_block_tolerance <= 1.0f)) {
    return absl::InvalidArgumentError("odometry pyramid: depth_block_tolerance not in [0, 1]");
  }
  return absl::OkStatus();
}

absl::StatusOr<OdometryPyramid> BuildOdometryPyramid(const RgbdFrame& frame,
                                                     const PinholeIntrinsics& k,
                                                     const OdometryPyramidOptions& options) {
  if (absl::Status s = ValidateOdometryPyramidOptions(options); !s.ok()) return s;
  const int w = k.width, h = k.height;
  if (w <= 0 || h <= 0 || frame.color.width != w || frame.color.height != h ||
      frame.color.channels != 3 || frame.depth.width != w || frame.depth.height != h ||
      frame.depth.channels != 1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "odometry: frame is colour %dx%dx%d, depth %dx%dx%d; the intrinsics say %dx%d",
        frame.color.width, frame.color.height, frame.color.channels, frame.depth.width,
        frame.depth.height, frame.depth.channels, w, h));
  }
  OdometryLevel level;
  level.width = w;
  level.height = h;
  level.fx = static_cast<float>(k.fx);
  level.fy = static_cast<float>(k.fy);
  level.cx = static_cast<float>(k.cx);
  level.cy = static_cast<float>(k.cy);
  const size_t n = static_cast<size_t>(w) * h;
  level.intensity.resize(n);
  level.depth.resize(n);
  for (size_t i = 0; i < n; ++i) {
    level.intensity[i] = Luma(frame.color.data.data() + 3 * i);
    const float d = frame.depth.data[i];
    level.depth[i] = (d > options.min_depth && d <= options.max_depth) ? d : 0.0f;
  }
  OdometryPyramid pyramid;
  while (level.width > options.max_width && level.width / 2 >= options.min_width) {
    level = HalfLevel(level, options.depth_block_tolerance);
  }
  for (;;) {
    const bool last = level.width / 2 < options.min_width || level.height / 2 < 2;
    OdometryLevel next;
    if (!last) next = HalfLevel(level, options.depth_block_tolerance);
    ComputeGradients(&level);
    pyramid.levels.push_back(std::move(level));
    if (last) break;
    level = std::move(next);
  }
  for (float d : pyramid.levels.front().depth) pyramid.valid_depth += d > 0.0f;
  return pyramid;
}

}  // namespace plx

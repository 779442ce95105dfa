// What one tracking ray contributes (residuals and their pose Jacobians), and how those are
// summed into the normal equations. The per-ray terms are computed by the shared kernel
// (core/kernels/tracking_impl.h); each backend sums them with AccumulateTrackingTerm.
#pragma once

#include <cstdint>

#include "core/common/host_device.h"
#include "core/grid/render_options.h"
#include "core/math/depth_noise.h"

namespace plx {

inline constexpr int kTrackingResiduals = 4;  // r, g, b, range
inline constexpr int kPoseDim = 6;
inline constexpr int kNormalUpper = kPoseDim * (kPoseDim + 1) / 2;  // 21

struct TrackingRayTerm {
  float residual[kTrackingResiduals];            // rendered - measured
  float jacobian[kTrackingResiduals][kPoseDim];  // d rendered / d xi
  float weight[kTrackingResiduals];              // 1 / noise scale; 0 leaves the residual out
};

struct TrackingParams {
  RenderOptions render;
  float color_sigma = 0.1f;        // colour noise scale (image units)
  DepthNoiseModel depth_noise;     // range noise scale grows with depth
  float depth_sigma_floor = 0.01f; // metres; never trust depth more than this
  float min_opacity = 0.9f;        // rays the map does not (almost) fully render are left out
  float max_depth = 10.0f;
  bool use_color = true;
  bool use_depth = true;
  // Paper mode (Adam): fixed L1 weights 0.5 * mean colour + 1.0 * mean depth, no noise scales.
  bool l1_paper_weights = false;
};

enum class TrackingLoss { kHuber, kL1 };

// Sums over rays: the Gauss-Newton normal equations H = sum w J^T J, g = sum w J^T e (e the
// scaled residual, w the robust weight) and the robust cost.
struct TrackingSums {
  double H[kNormalUpper];  // upper triangle, row-major
  double g[kPoseDim];
  double cost;
  double residual_sq;      // sum of squared scaled residuals (before robust weighting)
  double residual_count;
  double valid_rays;

  PLX_HD void Clear() {
    for (double& h : H) h = 0.0;
    for (double& x : g) x = 0.0;
    cost = residual_sq = residual_count = valid_rays = 0.0;
  }
  PLX_HD void Add(const TrackingSums& o) {
    for (int i = 0; i < kNormalUpper; ++i) H[i] += o.H[i];
    for (int i = 0; i < kPoseDim; ++i) g[i] += o.g[i];
    cost += o.cost;
    residual_sq += o.residual_sq;
    residual_count += o.residual_count;
    valid_rays += o.valid_rays;
  }
};

// Huber: rho(e) = e^2 / 2 inside k, k |e| - k^2 / 2 outside (IRLS weight min(1, k / |e|)).
// L1: rho(e) = |e|; only the gradient g is meaningful (for Adam).
// `scale[0]` (colour) and `scale[1]` (depth) stretch the noise scales, e.g. to the spread of
// the current residuals while the pose is still far off.
PLX_HD void AccumulateTrackingTerm(const TrackingRayTerm& term, TrackingLoss loss, float huber_k,
                                   const float scale[2], TrackingSums* sums) {
  bool any = false;
  for (int n = 0; n < kTrackingResiduals; ++n) {
    const float s = term.weight[n] / scale[n < 3 ? 0 : 1];
    if (s <= 0.0f) continue;
    any = true;
    const double e = static_cast<double>(term.residual[n]) * s;
    const double abs_e = e < 0 ? -e : e;
    double js[kPoseDim];
    for (int i = 0; i < kPoseDim; ++i) js[i] = static_cast<double>(term.jacobian[n][i]) * s;
    sums->residual_sq += e * e;
    sums->residual_count += 1.0;
    if (loss == TrackingLoss::kL1) {
      sums->cost += abs_e;
      const double sign = e > 0 ? 1.0 : (e < 0 ? -1.0 : 0.0);
      for (int i = 0; i < kPoseDim; ++i) sums->g[i] += sign * js[i];
      continue;
    }
    const double w = abs_e <= huber_k ? 1.0 : huber_k / abs_e;
    sums->cost += abs_e <= huber_k ? 0.5 * e * e : huber_k * (abs_e - 0.5 * huber_k);
    int k = 0;
    for (int i = 0; i < kPoseDim; ++i) {
      sums->g[i] += w * js[i] * e;
      for (int j = i; j < kPoseDim; ++j) sums->H[k++] += w * js[i] * js[j];
    }
  }
  if (any) sums->valid_rays += 1.0;
}

}  // namespace plx

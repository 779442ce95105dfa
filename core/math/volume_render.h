// Front-to-back compositing along a ray (DESIGN.md §6) and its backward pass (§7, paper
// eq. 8-10). With alpha_i = 1 - exp(-sigma_i dt), w_i = T_i alpha_i, T_{i+1} = T_i (1 - alpha_i):
//   C = sum_i w_i c_i + T_N bg,   D = sum_i w_i t_i.
// The backward pass walks the same samples again with a running remainder
//   A_i = (value rendered) - sum_{j<=i} w_j v_j,
// which gives d value / d sigma_i = dt (T_{i+1} v_i - A_i) without storing the samples.
#pragma once

#include <cmath>

#include "core/common/host_device.h"

namespace plx {

// Advances the transmittance over one sample; returns the sample's weight w_i.
template <typename T>
PLX_HD T CompositeForwardStep(T sigma, T dt, T* transmittance) {
  const T keep = exp(-sigma * dt);
  const T weight = *transmittance * (T(1) - keep);
  *transmittance *= keep;
  return weight;
}

// State of the backward walk for N rendered quantities sharing one density (e.g. N = 1 for a
// loss-weighted sum, N = 4 for r, g, b and depth).
template <typename T, int N>
struct CompositeBackwardState {
  T remainder[N];   // init: the rendered values (including background terms)
  T transmittance;  // init: 1
};

template <typename T, int N>
PLX_HD CompositeBackwardState<T, N> StartCompositeBackward(const T rendered[N]) {
  CompositeBackwardState<T, N> state;
  for (int n = 0; n < N; ++n) state.remainder[n] = rendered[n];
  state.transmittance = T(1);
  return state;
}

// One sample of the backward walk. `values` are the per-sample quantities v_i being composited
// (colour channels, sample distance, or a loss-weighted sum of them). Writes
// d rendered[n] / d sigma_i to dsigma[n] and returns the sample weight w_i (= d rendered / d v_i).
template <typename T, int N>
PLX_HD T CompositeBackwardStep(T sigma, T dt, const T values[N],
                               CompositeBackwardState<T, N>* state, T dsigma[N]) {
  const T keep = exp(-sigma * dt);
  const T weight = state->transmittance * (T(1) - keep);
  const T next_transmittance = state->transmittance * keep;
  for (int n = 0; n < N; ++n) {
    state->remainder[n] -= weight * values[n];
    dsigma[n] = dt * (next_transmittance * values[n] - state->remainder[n]);
  }
  state->transmittance = next_transmittance;
  return weight;
}

// Colour activation: max(0, sh . basis + 0.5) per channel; `unclamped[c]` records where the
// gradient flows. Unbounded above like Plenoxels; metrics clamp to [0, 1].
template <typename T>
PLX_HD T ActivateColor(T raw, bool* unclamped) {
  const T value = raw + T(0.5);
  *unclamped = value > T(0);
  return *unclamped ? value : T(0);
}

}  // namespace plx

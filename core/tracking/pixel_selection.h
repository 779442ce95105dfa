// Which pixels the map tracker casts its rays through. Rendering a ray against the map is the
// tracker's whole cost, so the rays it can afford should go where a residual says something
// about the pose: spread over the image (a cluster constrains little), on texture for the colour
// residuals, and off depth discontinuities, where a pixel mixes two surfaces and its depth
// residual is biased whichever way the pose moves.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "core/common/unified_allocator.h"
#include "core/geometry/rgbd_frame.h"

namespace plx {

enum class PixelSampling {
  kUniform,      // uniform over pixels with valid depth (the paper's choice)
  kInformative,  // spread, weighted towards colour gradient, off depth edges (see below)
};

struct PixelSelectionOptions {
  PixelSampling sampling = PixelSampling::kInformative;
  float max_depth = 10.0f;  // metres: farther depth is not a measurement
  // kInformative: a pixel's weight is the mean gradient plus its own gradient capped at
  // gradient_cap times the mean, so half the rays follow texture and half cover the surfaces
  // (depth residuals need no texture), and no single strong edge takes them all.
  float gradient_cap = 4.0f;
  // kInformative: a pixel whose 4-neighbours' depth differs by more than this fraction of its
  // own (or is missing) sits on a depth discontinuity and is not chosen.
  float depth_edge_fraction = 0.03f;
};

// Scratch a caller keeps between frames so selection allocates nothing in steady state.
struct PixelSelectionScratch {
  std::vector<int32_t> candidates;
  std::vector<double> cumulative;
};

// Fills `out` with `count` pixel indices (row-major, with repetition when weights demand it) in
// random order, so any prefix is itself a spread sample (the coarse level uses the first
// rays / coarse_divisor). Empty when no pixel has valid depth. Deterministic given `rng`.
void SelectTrackingPixels(const RgbdFrame& frame, const PixelSelectionOptions& options, int count,
                          std::mt19937* rng, PixelSelectionScratch* scratch,
                          UnifiedVector<int32_t>* out);

}  // namespace plx

// Learning-rate schedules of the mapping optimiser.
#pragma once

#include <algorithm>
#include <cmath>

namespace plx {

// Log-linear decay from lr_start to lr_end over progress in [0, 1], optionally with a sine
// warm-up from lr * warmup_multiplier over the first warmup_fraction (Plenoxels' schedule).
inline double LogLinearLearningRate(double lr_start, double lr_end, double progress,
                                    double warmup_fraction = 0.0,
                                    double warmup_multiplier = 1.0) {
  const double t = std::clamp(progress, 0.0, 1.0);
  double scale = 1.0;
  if (warmup_fraction > 0.0) {
    const double w = std::clamp(t / warmup_fraction, 0.0, 1.0);
    scale = warmup_multiplier + (1.0 - warmup_multiplier) * std::sin(0.5 * M_PI * w);
  }
  return scale * std::exp((1.0 - t) * std::log(lr_start) + t * std::log(lr_end));
}

}  // namespace plx

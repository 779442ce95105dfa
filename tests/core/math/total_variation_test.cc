#include "core/math/total_variation.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace plx {
namespace {

float Tv(const float v[4], float lambda) {
  const float dx = v[1] - v[0], dy = v[2] - v[0], dz = v[3] - v[0];
  return lambda * std::sqrt(dx * dx + dy * dy + dz * dz + 1e-9f);
}

TEST(TvTest, GradientMatchesCentralDifferences) {
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  for (int trial = 0; trial < 20; ++trial) {
    float v[4] = {u(rng), u(rng), u(rng), u(rng)};
    float g[4];
    TvGradient(v, 0.3f, g);
    for (int i = 0; i < 4; ++i) {
      float vp[4], vm[4];
      std::copy(v, v + 4, vp);
      std::copy(v, v + 4, vm);
      vp[i] += 1e-3f;
      vm[i] -= 1e-3f;
      // float differences: |dTV| ~ 0.3 * 1e-3, rounding ~1e-7 relative: 1e-3 absolute is ample
      EXPECT_NEAR(g[i], (Tv(vp, 0.3f) - Tv(vm, 0.3f)) / 2e-3f, 2e-3f) << i;
    }
  }
}

}  // namespace
}  // namespace plx

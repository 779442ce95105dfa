#include "core/math/volume_render.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/math/spherical_harmonics.h"

namespace plx {
namespace {

struct Samples {
  std::vector<double> sigma, t;
  std::vector<std::array<double, 3>> color;
};

// Renders colour (with background) and depth of the samples, the way RenderRay composites.
std::array<double, 4> Render(const Samples& s, double dt, const double bg[3]) {
  std::array<double, 4> out = {0, 0, 0, 0};
  double trans = 1;
  for (size_t i = 0; i < s.sigma.size(); ++i) {
    const double w = CompositeForwardStep(s.sigma[i], dt, &trans);
    for (int c = 0; c < 3; ++c) out[c] += w * s.color[i][c];
    out[3] += w * s.t[i];
  }
  for (int c = 0; c < 3; ++c) out[c] += trans * bg[c];
  return out;
}

Samples RandomSamples(std::mt19937& rng, int n) {
  std::uniform_real_distribution<double> sig(0.0, 40.0), col(0.0, 1.0);
  Samples s;
  for (int i = 0; i < n; ++i) {
    s.sigma.push_back(sig(rng));
    s.t.push_back(1.0 + 0.01 * i);
    s.color.push_back({col(rng), col(rng), col(rng)});
  }
  return s;
}

TEST(VolumeRenderTest, BackwardMatchesCentralDifferencesForColorAndDepth) {
  std::mt19937 rng(3);
  const double dt = 0.01, bg[3] = {0.2, 0.5, 0.9};
  for (int trial = 0; trial < 20; ++trial) {
    const Samples s = RandomSamples(rng, 12);
    const std::array<double, 4> rendered = Render(s, dt, bg);
    CompositeBackwardState<double, 4> state = StartCompositeBackward<double, 4>(rendered.data());
    for (size_t i = 0; i < s.sigma.size(); ++i) {
      const double values[4] = {s.color[i][0], s.color[i][1], s.color[i][2], s.t[i]};
      double dsigma[4];
      const double w = CompositeBackwardStep<double, 4>(s.sigma[i], dt, values, &state, dsigma);
      // d rendered / d sigma_i against central differences.
      const double h = 1e-5;
      Samples sp = s, sm = s;
      sp.sigma[i] += h;
      sm.sigma[i] -= h;
      const auto rp = Render(sp, dt, bg), rm = Render(sm, dt, bg);
      for (int n = 0; n < 4; ++n) {
        EXPECT_NEAR(dsigma[n], (rp[n] - rm[n]) / (2 * h), 1e-8) << "sample " << i << " out " << n;
      }
      // d colour / d c_i is the sample weight.
      Samples cp = s, cm = s;
      cp.color[i][1] += h;
      cm.color[i][1] -= h;
      EXPECT_NEAR(w, (Render(cp, dt, bg)[1] - Render(cm, dt, bg)[1]) / (2 * h), 1e-9);
    }
    // After the walk the remainder is the background term alone.
    double trans = state.transmittance;
    EXPECT_NEAR(state.remainder[0], trans * bg[0], 1e-12);
    EXPECT_NEAR(state.remainder[3], 0.0, 1e-12);
  }
}

TEST(VolumeRenderTest, WeightsSumToOpacity) {
  std::mt19937 rng(4);
  const Samples s = RandomSamples(rng, 30);
  double trans = 1, sum = 0;
  for (double sigma : s.sigma) sum += CompositeForwardStep(sigma, 0.01, &trans);
  EXPECT_NEAR(sum, 1.0 - trans, 1e-14);
}

TEST(VolumeRenderTest, ColorActivationClampsBelowZeroOnly) {
  bool unclamped;
  EXPECT_DOUBLE_EQ(ActivateColor(0.2, &unclamped), 0.7);
  EXPECT_TRUE(unclamped);
  EXPECT_DOUBLE_EQ(ActivateColor(-0.8, &unclamped), 0.0);
  EXPECT_FALSE(unclamped);
  EXPECT_DOUBLE_EQ(ActivateColor(0.9, &unclamped), 1.4);  // no upper clamp (Plenoxels)
}

TEST(SphericalHarmonicsTest, DcReproducesColorAndBasisIsOrthonormalOnTheSphere) {
  double basis[kShBasisCount];
  EvalShBasis(Vec3d{0, 0, 1}, basis);
  EXPECT_NEAR(ShDcForColor(0.8) * basis[0] + 0.5, 0.8, 1e-15);
  // Monte Carlo check of orthonormality with a fixed seed: |<Y_i, Y_j> - delta_ij| small.
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0, 1);
  double gram[9][9] = {};
  const int count = 200000;
  for (int s = 0; s < count; ++s) {
    Vec3d d{n(rng), n(rng), n(rng)};
    d = Normalized(d);
    EvalShBasis(d, basis);
    for (int i = 0; i < 9; ++i)
      for (int j = 0; j < 9; ++j) gram[i][j] += basis[i] * basis[j];
  }
  for (int i = 0; i < 9; ++i) {
    for (int j = 0; j < 9; ++j) {
      const double integral = gram[i][j] / count * 4 * M_PI;
      EXPECT_NEAR(integral, i == j ? 1.0 : 0.0, 0.03) << i << "," << j;
    }
  }
}

}  // namespace
}  // namespace plx

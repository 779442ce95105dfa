#include "core/math/trilinear.h"

#include <random>

#include <gtest/gtest.h>

namespace plx {
namespace {

double Value(const double v[8], const Vec3d& f) {
  double w[8];
  TrilinearWeights(f, w);
  return Trilerp(v, w);
}

TEST(TrilinearTest, ReproducesCornersAndAffineFields) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-2, 2);
  double v[8];
  for (double& x : v) x = u(rng);
  for (int c = 0; c < 8; ++c) {
    const Vec3d corner{double(c & 1), double((c >> 1) & 1), double((c >> 2) & 1)};
    EXPECT_NEAR(Value(v, corner), v[c], 1e-15);
  }
  // An affine field a + b.x is reproduced exactly everywhere inside the cell.
  const double a = 0.3, b[3] = {1.5, -0.7, 2.0};
  double affine[8];
  for (int c = 0; c < 8; ++c) {
    affine[c] = a + b[0] * (c & 1) + b[1] * ((c >> 1) & 1) + b[2] * ((c >> 2) & 1);
  }
  const Vec3d f{0.25, 0.6, 0.9};
  EXPECT_NEAR(Value(affine, f), a + b[0] * f.x + b[1] * f.y + b[2] * f.z, 1e-14);
  const Vec3d g = TrilinearGradient(affine, f);
  EXPECT_NEAR(g.x, b[0], 1e-14);
  EXPECT_NEAR(g.y, b[1], 1e-14);
  EXPECT_NEAR(g.z, b[2], 1e-14);
}

TEST(TrilinearTest, GradientMatchesCentralDifferences) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-3, 3), p(0.05, 0.95);
  for (int trial = 0; trial < 50; ++trial) {
    double v[8];
    for (double& x : v) x = u(rng);
    const Vec3d f{p(rng), p(rng), p(rng)};
    const Vec3d g = TrilinearGradient(v, f);
    const double h = 1e-6;
    for (int a = 0; a < 3; ++a) {
      Vec3d fp = f, fm = f;
      (a == 0 ? fp.x : a == 1 ? fp.y : fp.z) += h;
      (a == 0 ? fm.x : a == 1 ? fm.y : fm.z) -= h;
      const double numeric = (Value(v, fp) - Value(v, fm)) / (2 * h);
      EXPECT_NEAR(g[a], numeric, 1e-8) << "axis " << a;
    }
  }
}

TEST(TrilinearTest, WeightsAreTheDerivativeWithRespectToCorners) {
  const Vec3d f{0.3, 0.8, 0.45};
  double w[8];
  TrilinearWeights(f, w);
  double sum = 0;
  for (double x : w) sum += x;
  EXPECT_NEAR(sum, 1.0, 1e-15);
  double v[8] = {0.1, -0.4, 0.9, 1.3, -2.0, 0.5, 0.7, -0.2};
  for (int c = 0; c < 8; ++c) {
    double vp[8], vm[8];
    std::copy(v, v + 8, vp);
    std::copy(v, v + 8, vm);
    vp[c] += 1e-6;
    vm[c] -= 1e-6;
    EXPECT_NEAR(w[c], (Value(vp, f) - Value(vm, f)) / 2e-6, 1e-9);
  }
}

}  // namespace
}  // namespace plx

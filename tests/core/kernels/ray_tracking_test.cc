#include "core/kernels/ray_tracking.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/geometry/kernel_camera.h"
#include "core/geometry/se3.h"
#include "core/grid/sparse_grid.h"

namespace plx {
namespace {

TEST(ShBasisGradientTest, MatchesCentralDifferences) {
  std::mt19937 rng(61);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3d d{n(rng), n(rng), n(rng)};
    double grad[kShBasisCount][3];
    EvalShBasisGradient(d, grad);
    for (int a = 0; a < 3; ++a) {
      Vec3d dp = d, dm = d;
      const double h = 1e-6;
      (a == 0 ? dp.x : a == 1 ? dp.y : dp.z) += h;
      (a == 0 ? dm.x : a == 1 ? dm.y : dm.z) -= h;
      double bp[kShBasisCount], bm[kShBasisCount];
      EvalShBasis(dp, bp);
      EvalShBasis(dm, bm);
      for (int k = 0; k < kShBasisCount; ++k) {
        EXPECT_NEAR(grad[k][a], (bp[k] - bm[k]) / (2 * h), 1e-8) << k << "," << a;
      }
    }
  }
}

TEST(PoseJacobianTest, PointAndDirectionGradientsMatchCentralDifferences) {
  std::mt19937 rng(62);
  std::normal_distribution<double> n(0.0, 1.0);
  Vector6d xi0;
  for (int i = 0; i < 6; ++i) xi0[i] = 0.5 * n(rng);
  const SE3 pose = SE3::Exp(xi0);
  const Vec3d q{0.3, -0.2, 1.7};
  const Vec3d g{0.7, 1.1, -0.4};  // a fixed linear functional of the point
  double analytic[6], analytic_dir[6];
  PointGradientToPose(ToRigidTransform<double>(pose), q, g, analytic);
  DirectionGradientToPose(ToRigidTransform<double>(pose), q, g, analytic_dir);
  for (int i = 0; i < 6; ++i) {
    Vector6d e = Vector6d::Zero();
    const double h = 1e-6;
    e[i] = h;
    auto f = [&](const SE3& T, bool direction) {
      const Eigen::Vector3d p = direction ? T.rotation() * Eigen::Vector3d(q.x, q.y, q.z)
                                          : T * Eigen::Vector3d(q.x, q.y, q.z);
      return g.x * p.x() + g.y * p.y() + g.z * p.z();
    };
    const double numeric = (f(pose * SE3::Exp(e), false) - f(pose * SE3::Exp(-e), false)) / (2 * h);
    const double numeric_dir =
        (f(pose * SE3::Exp(e), true) - f(pose * SE3::Exp(-e), true)) / (2 * h);
    EXPECT_NEAR(analytic[i], numeric, 1e-8) << i;
    EXPECT_NEAR(analytic_dir[i], numeric_dir, 1e-8) << i;
  }
}

// The full chain "pose -> rendered colour and depth" on a double-precision grid, against central
// differences of the renderer itself.
class RayPoseJacobianTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<BrickCoord> bricks;
    for (int x = -1; x <= 0; ++x)
      for (int y = -1; y <= 0; ++y)
        for (int z = 0; z <= 1; ++z) bricks.push_back({x, y, z});
    ASSERT_TRUE(grid_.AllocateBricks(bricks).ok());
    std::mt19937 rng(63);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    density_.resize(grid_.num_vertices());
    sh_.resize(grid_.num_vertices() * kShCoeffCount);
    // A smooth random field: sums of a few sinusoids, so the spatial gradients are informative.
    const double a = u(rng) * 6, b = u(rng) * 6, c = u(rng) * 6;
    const ContiguousBrickTables<double> tables(density_.data(), sh_.data(), grid_.num_bricks());
    const GridViewT<double> g = tables.ViewOf(grid_);
    for (int64_t i = 0; i < grid_.num_vertices(); ++i) {
      int v[3];
      g.VertexCoords(i, v);
      const Vec3d p = g.VertexPosition(v[0], v[1], v[2]);
      density_[i] =
          6.0 + 5.0 * std::sin(a * p.x + 1.0) * std::cos(b * p.y) + 3.0 * std::sin(c * p.z);
      for (int j = 0; j < kShCoeffCount; ++j) {
        sh_[i * kShCoeffCount + j] = 0.15 * std::sin((j + 1) * p.x + b * p.y - a * p.z + j);
      }
    }
    options_.near = 0.0;
    options_.far = 10.0;
    options_.stop_transmittance = 0.0;
    options_.sigma_threshold = 0.0;
    options_.background[0] = 0.2;
    options_.background[1] = 0.5;
    options_.background[2] = 0.8;
    // A camera 1 m in front of the grid looking at it along +z, tilted a little.
    Vector6d xi;
    xi << 0.05, -0.03, -1.2, 0.05, -0.08, 0.3;
    pose_ = SE3::Exp(xi);
  }

  std::array<double, 5> Render(const SE3& pose, const Vec3d& d_camera) {
    const ContiguousBrickTables<double> tables(density_.data(), sh_.data(), grid_.num_bricks());
    const GridViewT<double> g = tables.ViewOf(grid_);
    const RigidTransform<double> X = ToRigidTransform<double>(pose);
    const RayRenderResult<double> r = RenderRay(g, X.translation(), X.Rotate(d_camera), options_);
    return {r.color[0], r.color[1], r.color[2], r.depth, r.opacity};
  }

  SparseGrid grid_{0.05f};
  std::vector<double> density_, sh_;
  RenderOptionsT<double> options_;
  SE3 pose_;
};

TEST_F(RayPoseJacobianTest, MatchesCentralDifferencesOfTheRenderer) {
  const ContiguousBrickTables<double> tables(density_.data(), sh_.data(), grid_.num_bricks());
  const GridViewT<double> g = tables.ViewOf(grid_);
  int rays = 0;
  for (double dx : {-0.15, 0.0, 0.12}) {
    for (double dy : {-0.1, 0.07}) {
      const Vec3d d_camera = Normalized(Vec3d{dx, dy, 1.0});
      const RayPoseJacobian<double> jac =
          RenderRayPoseJacobian(g, ToRigidTransform<double>(pose_), d_camera, options_);
      if (jac.samples < 5 || jac.opacity < 0.3) continue;
      ++rays;
      const auto base = Render(pose_, d_camera);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(jac.color[c], base[c], 1e-12);
      EXPECT_NEAR(jac.depth, base[3], 1e-12);
      for (int i = 0; i < 6; ++i) {
        Vector6d e = Vector6d::Zero();
        const double h = 1e-6;
        e[i] = h;
        const auto plus = Render(pose_ * SE3::Exp(e), d_camera);
        const auto minus = Render(pose_ * SE3::Exp(-e), d_camera);
        for (int c = 0; c < 3; ++c) {
          const double numeric = (plus[c] - minus[c]) / (2 * h);
          EXPECT_NEAR(jac.d_color[c][i], numeric, 1e-6 + 1e-5 * std::abs(numeric))
              << "colour " << c << " xi " << i;
        }
        const double numeric = (plus[3] - minus[3]) / (2 * h);
        EXPECT_NEAR(jac.d_depth[i], numeric, 1e-6 + 1e-5 * std::abs(numeric)) << "depth xi " << i;
        const double numeric_opacity = (plus[4] - minus[4]) / (2 * h);
        EXPECT_NEAR(jac.d_opacity[i], numeric_opacity, 1e-6 + 1e-5 * std::abs(numeric_opacity))
            << "opacity xi " << i;
      }
    }
  }
  EXPECT_GE(rays, 4);
}

}  // namespace
}  // namespace plx

#include "core/kernels/ray_mapping_backward.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/grid/sparse_grid.h"
#include "core/kernels/ray_render.h"

namespace plx {
namespace {

// A small double-precision grid with smooth random values, and a ray through it.
class MappingBackwardTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(grid_.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0},
                                                              {1, 1, 0}, {0, 0, 1}, {1, 1, 1}})
                    .ok());
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> dens(2.0, 30.0), sh(-0.05, 0.05);
    density_.resize(grid_.num_vertices());
    sh_.resize(grid_.num_vertices() * 27);
    for (double& v : density_) v = dens(rng);
    for (double& v : sh_) v = sh(rng);
    options_.near = 0.0;
    options_.far = 10.0;
    options_.stop_transmittance = 0.0;  // no early stop: keeps the loss smooth for differences
    options_.sigma_threshold = 0.0;
    options_.background[0] = 0.3;
    options_.background[1] = 0.6;
    options_.background[2] = 0.9;
    origin_ = {0.11, 0.13, -0.2};
    dir_ = Normalized(Vec3d{0.45, 0.35, 1.0});
  }

  // A linear functional of the rendering: L = a . colour + b depth.
  double Loss() {
    const ContiguousBrickTables<double> tables(density_.data(), sh_.data(), grid_.num_bricks());
    const GridViewT<double> g = tables.ViewOf(grid_);
    const RayRenderResult<double> r = RenderRay(g, origin_, dir_, options_);
    return a_[0] * r.color[0] + a_[1] * r.color[1] + a_[2] * r.color[2] + b_ * r.depth;
  }

  SparseGrid grid_{0.1f};
  std::vector<double> density_, sh_;
  RenderOptionsT<double> options_;
  Vec3d origin_, dir_;
  double a_[3] = {0.7, -1.3, 0.4};
  double b_ = 0.8;
};

TEST_F(MappingBackwardTest, GradientsMatchCentralDifferences) {
  const ContiguousBrickTables<double> tables(density_.data(), sh_.data(), grid_.num_bricks());
  GridViewT<double> g = tables.ViewOf(grid_);
  const RayRenderResult<double> fwd = RenderRay(g, origin_, dir_, options_);
  ASSERT_GT(fwd.samples, 10);
  ASSERT_GT(fwd.opacity, 0.5);
  std::vector<double> gd(density_.size(), 0.0), gs(sh_.size(), 0.0);
  std::vector<uint8_t> touched(density_.size(), 0), brick_touched(grid_.num_bricks(), 0);
  GridGradViewT<double> grad{gd.data(), gs.data(), touched.data(), brick_touched.data()};
  MappingRayBackward(g, grad, origin_, dir_, options_, fwd, a_, b_, 0.0);

  int checked_density = 0, checked_sh = 0;
  const double h = 1e-6;
  for (size_t i = 0; i < density_.size(); ++i) {
    if (!touched[i]) {
      EXPECT_EQ(gd[i], 0.0);
      continue;
    }
    const double saved = density_[i];
    density_[i] = saved + h;
    const double lp = Loss();
    density_[i] = saved - h;
    const double lm = Loss();
    density_[i] = saved;
    EXPECT_NEAR(gd[i], (lp - lm) / (2 * h), 1e-7 + 1e-5 * std::abs(gd[i])) << "density " << i;
    ++checked_density;
    for (int j = 0; j < 27; j += 4) {
      double& v = sh_[i * 27 + j];
      const double s = v;
      v = s + h;
      const double sp = Loss();
      v = s - h;
      const double sm = Loss();
      v = s;
      EXPECT_NEAR(gs[i * 27 + j], (sp - sm) / (2 * h), 1e-8 + 1e-5 * std::abs(gs[i * 27 + j]))
          << "sh " << i << "," << j;
      ++checked_sh;
    }
  }
  EXPECT_GT(checked_density, 20);
  for (size_t i = 0; i < touched.size(); ++i) {
    if (touched[i]) {
      EXPECT_EQ(brick_touched[i / kBrickVertices], 1) << "vertex " << i;
    }
  }
  EXPECT_GT(checked_sh, 100);
}

}  // namespace
}  // namespace plx

#include "core/grid/ray_march.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/grid/sparse_grid.h"

namespace plx {
namespace {

// Every lattice sample whose cell has a stored corner, found without empty-space skipping.
std::vector<double> BruteForceSamples(const GridViewT<double>& g, Vec3d o, Vec3d d, double near,
                                      double far, double step) {
  std::vector<double> ts;
  for (int64_t k = static_cast<int64_t>(std::ceil(near / step)); k * step <= far; ++k) {
    const double t = k * step;
    const Vec3d q = g.ToGrid(o + d * t);
    bool inside = true;
    for (int a = 0; a < 3; ++a) inside &= q[a] >= 0 && q[a] <= g.vertex_extent(a) - 1;
    if (!inside) continue;
    CellSample<double> s;
    LocateCell(g, q, &s);
    bool any = false;
    for (int c = 0; c < 8; ++c) any |= s.slots[c] >= 0;
    if (any) ts.push_back(t);
  }
  return ts;
}

TEST(RayMarchTest, SkippingVisitsEverySampleThatTouchesStoredVertices) {
  SparseGrid grid(0.05f);
  std::vector<BrickCoord> bricks;
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> b(-3, 3);
  for (int i = 0; i < 25; ++i) bricks.push_back({b(rng), b(rng), b(rng)});
  ASSERT_TRUE(grid.AllocateBricks(bricks).ok());
  std::vector<double> density(grid.num_vertices(), 1.0), sh(grid.num_vertices() * 27, 0.0);
  const ContiguousBrickTables<double> tables(density.data(), sh.data(), grid.num_bricks());
  const GridViewT<double> g = tables.ViewOf(grid);

  std::normal_distribution<double> n(0, 1);
  int total_samples = 0;
  for (int r = 0; r < 200; ++r) {
    // From outside the bricks towards a random point among them.
    const Vec3d o = Normalized(Vec3d{n(rng), n(rng), n(rng)}) * 3.0;
    const Vec3d target{n(rng) * 0.6, n(rng) * 0.6, n(rng) * 0.6};
    const Vec3d d = Normalized(target - o);
    const double step = 0.5 * 0.05;
    std::vector<double> visited;
    MarchRay(g, o, d, 0.0, 6.0, step, [&](double t, const CellSample<double>&) {
      visited.push_back(t);
      return true;
    });
    const std::vector<double> expected = BruteForceSamples(g, o, d, 0.0, 6.0, step);
    // Skipping may visit extra samples in active blocks, never miss one with a stored corner.
    size_t j = 0;
    for (double t : expected) {
      while (j < visited.size() && visited[j] < t - 1e-12) ++j;
      ASSERT_LT(j, visited.size()) << "ray " << r << " missed t=" << t;
      EXPECT_NEAR(visited[j], t, 1e-12);
    }
    total_samples += static_cast<int>(expected.size());
  }
  EXPECT_GT(total_samples, 1000);  // the rays really cross the bricks
}

TEST(RayMarchTest, StopsWhenTheVisitorSaysSo) {
  SparseGrid grid(0.1f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}}).ok());
  std::vector<double> density(grid.num_vertices(), 1.0), sh(grid.num_vertices() * 27, 0.0);
  const ContiguousBrickTables<double> tables(density.data(), sh.data(), grid.num_bricks());
  const GridViewT<double> g = tables.ViewOf(grid);
  int count = 0;
  MarchRay(g, Vec3d{0.35, 0.35, -1.0}, Vec3d{0, 0, 1}, 0.0, 5.0, 0.05,
           [&](double, const CellSample<double>&) { return ++count < 3; });
  EXPECT_EQ(count, 3);
}

TEST(RayMarchTest, MissingTheGridVisitsNothing) {
  SparseGrid grid(0.1f);
  ASSERT_TRUE(grid.AllocateBricks(std::vector<BrickCoord>{{0, 0, 0}}).ok());
  std::vector<double> density(grid.num_vertices(), 1.0), sh(grid.num_vertices() * 27, 0.0);
  const ContiguousBrickTables<double> tables(density.data(), sh.data(), grid.num_bricks());
  const GridViewT<double> g = tables.ViewOf(grid);
  int count = 0;
  MarchRay(g, Vec3d{50, 50, 50}, Vec3d{1, 0, 0}, 0.0, 10.0, 0.05,
           [&](double, const CellSample<double>&) { return ++count > 0; });
  EXPECT_EQ(count, 0);
}

}  // namespace
}  // namespace plx

// The generated marching-cubes table, case by case: the triangles use exactly the edges the
// case crosses, fit kMaxCubeTriangles, and form a consistently oriented surface inside the cube
// whose open edges all lie on cube faces (where the neighbouring cell continues it).
#include "core/kernels/marching_cubes_table.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>
#include <utility>

namespace plx {
namespace {

// Corner offsets of a cube edge's ends.
std::pair<int, int> EdgeCorners(int e) {
  const int low = CubeEdgeLowCorner(e);
  return {low, low | (1 << CubeEdgeAxis(e))};
}

// Whether edges e and f lie on a common cube face (some axis where both are fixed at the same
// side).
bool ShareAFace(int e, int f) {
  const auto [e0, e1] = EdgeCorners(e);
  const auto [f0, f1] = EdgeCorners(f);
  for (int axis = 0; axis < 3; ++axis) {
    const int bit = 1 << axis;
    if (((e0 ^ e1) & bit) || ((f0 ^ f1) & bit)) continue;
    if ((e0 & bit) == (f0 & bit)) return true;
  }
  return false;
}

TEST(MarchingCubesTableTest, EveryCaseTriangulatesExactlyItsCrossedEdges) {
  MarchingCubesTable table;
  BuildMarchingCubesTable(&table);
  int most = 0;
  for (int c = 0; c < 256; ++c) {
    std::set<int> crossed, used;
    for (int e = 0; e < 12; ++e) {
      const auto [a, b] = EdgeCorners(e);
      if (((c >> a) & 1) != ((c >> b) & 1)) crossed.insert(e);
    }
    const int n = table.triangle_count[c];
    most = std::max(most, n);
    std::map<std::pair<int, int>, int> directed;
    for (int i = 0; i < 3 * n; ++i) {
      const int e = table.edges[c][i];
      ASSERT_GE(e, 0) << "case " << c;
      used.insert(e);
      const int f = table.edges[c][(i / 3) * 3 + (i % 3 + 1) % 3];
      ++directed[{e, f}];
    }
    EXPECT_EQ(used, crossed) << "case " << c;
    for (const auto& [edge, count] : directed) {
      EXPECT_EQ(count, 1) << "case " << c << ": a directed edge twice (orientation flips)";
      // An edge inside the cube is shared by two triangles in opposite directions; one that is
      // not must run along a cube face, where the neighbouring cell's triangles meet it.
      if (directed.count({edge.second, edge.first}) == 0) {
        EXPECT_TRUE(ShareAFace(edge.first, edge.second))
            << "case " << c << ": open edge " << edge.first << "-" << edge.second;
      }
    }
    for (int i = 3 * n; i < 3 * kMaxCubeTriangles; ++i) EXPECT_EQ(table.edges[c][i], -1);
  }
  EXPECT_EQ(most, kMaxCubeTriangles);
  EXPECT_EQ(table.triangle_count[0], 0);
  EXPECT_EQ(table.triangle_count[255], 0);
}

// One inside corner: a single triangle around it, counter-clockwise seen from outside (from the
// far side of the corner), i.e. its normal points away from the corner.
TEST(MarchingCubesTableTest, TrianglesFaceAwayFromTheInside) {
  MarchingCubesTable table;
  BuildMarchingCubesTable(&table);
  for (int corner = 0; corner < 8; ++corner) {
    const int c = 1 << corner;
    ASSERT_EQ(table.triangle_count[c], 1);
    double p[3][3];
    for (int v = 0; v < 3; ++v) {
      const int e = table.edges[c][v];
      const auto [a, b] = EdgeCorners(e);
      for (int axis = 0; axis < 3; ++axis) {
        p[v][axis] = 0.5 * (((a >> axis) & 1) + ((b >> axis) & 1));
      }
    }
    const double u[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double w[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                         u[0] * w[1] - u[1] * w[0]};
    double outward = 0.0;
    for (int axis = 0; axis < 3; ++axis) {
      outward += n[axis] * (p[0][axis] - ((corner >> axis) & 1));
    }
    EXPECT_GT(outward, 0.0) << "corner " << corner;
  }
}

}  // namespace
}  // namespace plx

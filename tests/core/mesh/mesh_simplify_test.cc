// Levels of detail (core/mesh/mesh_simplify.h): the budget is respected, a sphere keeps its
// shape within the error the simplifier reports (plus the chord error every triangle mesh of a
// sphere has), a flat square keeps its outline and area, every vertex of a level of detail is
// an input vertex with that vertex's own normal and colour, the triangles keep facing the way
// they did, and a budget the topology cannot reach is reached by clustering.
#include "core/mesh/mesh_simplify.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <tuple>
#include <vector>

#include "core/math/vec3.h"
#include "tests/mesh_checks.h"

namespace plx {
namespace mesh_simplify_test {

constexpr float kRadius = 0.5f;  // metres: a ball a room might hold

Vec3f Position(const TriangleMesh& m, int32_t v) {
  return Vec3f{m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]};
}

// An icosphere of `radius`: an icosahedron with every triangle split in four `levels` times,
// vertices pushed onto the sphere (20 * 4^levels triangles, closed, counter-clockwise seen from
// outside). Normals point outward; each vertex gets its own colour (its index in base 256) so
// a test can tell which input vertex an output vertex is.
TriangleMesh Icosphere(int levels, float radius) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3f> p = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0},
                          {0, -1, t}, {0, 1, t},  {0, -1, -t}, {0, 1, -t},
                          {t, 0, -1}, {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<int32_t, 3>> f = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int32_t, int32_t>, int32_t> middle;
    auto mid = [&](int32_t a, int32_t b) {
      const auto key = std::minmax(a, b);
      auto [it, inserted] = middle.try_emplace(key, static_cast<int32_t>(p.size()));
      if (inserted) p.push_back((p[a] + p[b]) * 0.5f);
      return it->second;
    };
    std::vector<std::array<int32_t, 3>> next;
    for (const auto& [a, b, c] : f) {
      const int32_t ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
      next.push_back({a, ab, ca});
      next.push_back({b, bc, ab});
      next.push_back({c, ca, bc});
      next.push_back({ab, bc, ca});
    }
    f.swap(next);
  }
  TriangleMesh mesh;
  for (size_t v = 0; v < p.size(); ++v) {
    const Vec3f n = p[v] * (1.0f / Norm(p[v]));
    const Vec3f x = n * radius;
    mesh.positions.insert(mesh.positions.end(), {x.x, x.y, x.z});
    mesh.normals.insert(mesh.normals.end(), {n.x, n.y, n.z});
    mesh.colors.insert(mesh.colors.end(), {static_cast<uint8_t>(v & 255),
                                           static_cast<uint8_t>((v >> 8) & 255),
                                           static_cast<uint8_t>(v >> 16)});
  }
  for (const auto& [a, b, c] : f) mesh.triangles.insert(mesh.triangles.end(), {a, b, c});
  return mesh;
}

// A flat, open square of side 1 m in z = 0 from n x n cells of two triangles (normals +Z,
// counter-clockwise seen from +Z).
TriangleMesh Square(int n) {
  TriangleMesh mesh;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      mesh.positions.insert(mesh.positions.end(),
                            {static_cast<float>(i) / n, static_cast<float>(j) / n, 0.0f});
      mesh.normals.insert(mesh.normals.end(), {0.0f, 0.0f, 1.0f});
      mesh.colors.insert(mesh.colors.end(), {static_cast<uint8_t>(i), static_cast<uint8_t>(j), 7});
    }
  }
  auto at = [n](int i, int j) { return static_cast<int32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.triangles.insert(mesh.triangles.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.insert(mesh.triangles.end(), {at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  return mesh;
}

// Twice the triangle's area along its (unnormalised) geometric normal.
Vec3f AreaNormal(const TriangleMesh& m, int64_t t) {
  const int32_t* f = &m.triangles[3 * t];
  return Cross(Position(m, f[1]) - Position(m, f[0]), Position(m, f[2]) - Position(m, f[0]));
}

// The largest |distance to the centre - radius| over points spread over every triangle (its
// corners, edge midpoints and barycentric grid): how far the surface left the sphere.
double MaxSphereDeviation(const TriangleMesh& m, float radius) {
  double worst = 0.0;
  constexpr int kSteps = 6;
  for (int64_t t = 0; t < m.num_triangles(); ++t) {
    const int32_t* f = &m.triangles[3 * t];
    const Vec3f a = Position(m, f[0]), b = Position(m, f[1]), c = Position(m, f[2]);
    for (int i = 0; i <= kSteps; ++i) {
      for (int j = 0; i + j <= kSteps; ++j) {
        const float u = static_cast<float>(i) / kSteps, v = static_cast<float>(j) / kSteps;
        const Vec3f x = a * (1.0f - u - v) + b * u + c * v;
        worst = std::max(worst, std::abs(static_cast<double>(Norm(x)) - radius));
      }
    }
  }
  return worst;
}

// Every vertex of `lod` is a vertex of `full` (same position), with that vertex's normal and
// colour.
void ExpectVerticesAreInputVertices(const TriangleMesh& full, const TriangleMesh& lod) {
  std::map<std::tuple<float, float, float>, int32_t> index;
  for (int32_t v = 0; v < full.num_vertices(); ++v) {
    index[{full.positions[3 * v], full.positions[3 * v + 1], full.positions[3 * v + 2]}] = v;
  }
  for (int32_t v = 0; v < lod.num_vertices(); ++v) {
    const auto it =
        index.find({lod.positions[3 * v], lod.positions[3 * v + 1], lod.positions[3 * v + 2]});
    ASSERT_NE(it, index.end()) << "vertex " << v << " is not an input vertex";
    for (int c = 0; c < 3; ++c) {
      ASSERT_EQ(lod.normals[3 * v + c], full.normals[3 * it->second + c]) << v;
      ASSERT_EQ(lod.colors[3 * v + c], full.colors[3 * it->second + c]) << v;
    }
  }
}

// Each vertex is used, and no triangle names a vertex twice.
void ExpectCompactAndNonDegenerate(const TriangleMesh& m) {
  ASSERT_TRUE(CheckTriangleMesh(m).ok());
  std::vector<bool> used(static_cast<size_t>(m.num_vertices()), false);
  for (int64_t t = 0; t < m.num_triangles(); ++t) {
    const int32_t* f = &m.triangles[3 * t];
    EXPECT_TRUE(f[0] != f[1] && f[1] != f[2] && f[0] != f[2]) << "triangle " << t;
    for (int c = 0; c < 3; ++c) used[f[c]] = true;
  }
  EXPECT_EQ(std::count(used.begin(), used.end(), false), 0) << "unused vertices";
}

TEST(MeshSimplifyTest, ASphereAtATenthKeepsItsShapeWithinTheReportedError) {
  const TriangleMesh full = Icosphere(5, kRadius);  // 20480 triangles, 10242 vertices
  ASSERT_EQ(full.num_triangles(), 20480);
  // The full mesh's own distance from the sphere: the sagitta of its chords.
  const double full_deviation = MaxSphereDeviation(full, kRadius);
  for (const int64_t budget : {int64_t{2048}, int64_t{500}}) {
    SCOPED_TRACE(budget);
    absl::StatusOr<SimplifiedMesh> lod = SimplifyMesh(full, budget);
    ASSERT_TRUE(lod.ok()) << lod.status();
    EXPECT_LE(lod->mesh.num_triangles(), budget);
    EXPECT_GE(lod->mesh.num_triangles(), budget * 9 / 10) << "stopped well short of the budget";
    EXPECT_EQ(lod->input_triangles, full.num_triangles());
    EXPECT_TRUE(lod->topology_kept);
    ExpectCompactAndNonDegenerate(lod->mesh);
    ExpectVerticesAreInputVertices(full, lod->mesh);
    // Still closed: every edge has exactly two triangles.
    const testing::EdgeUse edges = testing::CountEdgeUse(lod->mesh);
    EXPECT_EQ(edges.not_twice, 0);
    EXPECT_EQ(edges.same_direction, 0);
    // Every triangle still faces outward.
    for (int64_t t = 0; t < lod->mesh.num_triangles(); ++t) {
      const int32_t* f = &lod->mesh.triangles[3 * t];
      const Vec3f centre = Position(lod->mesh, f[0]) + Position(lod->mesh, f[1]) +
                           Position(lod->mesh, f[2]);
      ASSERT_GT(Dot(AreaNormal(lod->mesh, t), centre), 0.0f) << "triangle " << t << " flipped";
    }
    // The quadric error is the distance from the input's triangle planes; the sphere is within
    // the input's own chord error of those, so the two bound the level of detail's distance
    // from the sphere (the 5% covers the quadric's averaging over the collapsed planes).
    const double deviation = MaxSphereDeviation(lod->mesh, kRadius);
    EXPECT_GT(lod->error_m, 0.0);
    EXPECT_LE(deviation, 1.05 * (lod->error_m + full_deviation))
        << "error " << lod->error_m << " m, full mesh " << full_deviation << " m";
    // A tenth of the triangles of a 1 m ball still within 5 mm of it (measured: 4.0 mm; a
    // uniform mesh of 2048 triangles is 1.2 mm off, its chords' sagitta), a fortieth within
    // 2 cm (measured: 14.9 mm).
    EXPECT_LT(deviation, budget == 2048 ? 0.005 : 0.02);
    std::printf("sphere r %.2f m, %lld -> %lld triangles: error %.2f mm, off the sphere %.2f mm "
                "(full mesh %.2f mm)\n",
                kRadius, static_cast<long long>(full.num_triangles()),
                static_cast<long long>(lod->mesh.num_triangles()), 1000 * lod->error_m,
                1000 * deviation, 1000 * full_deviation);
  }
}

TEST(MeshSimplifyTest, AFlatSquareKeepsItsOutlineAreaAndFacing) {
  const TriangleMesh full = Square(60);  // 7200 triangles
  const absl::StatusOr<SimplifiedMesh> lod = SimplifyMesh(full, 72);
  ASSERT_TRUE(lod.ok()) << lod.status();
  EXPECT_LE(lod->mesh.num_triangles(), 72);
  ExpectCompactAndNonDegenerate(lod->mesh);
  ExpectVerticesAreInputVertices(full, lod->mesh);
  // Flat and in place: collapsing within a plane moves nothing off it; the border collapses
  // only along itself, so the outline and the area stay.
  EXPECT_NEAR(lod->error_m, 0.0, 1e-6);
  float area = 0.0f;
  float lo[2] = {1, 1}, hi[2] = {0, 0};
  for (int64_t t = 0; t < lod->mesh.num_triangles(); ++t) {
    const Vec3f n = AreaNormal(lod->mesh, t);
    EXPECT_GT(n.z, 0.0f) << "triangle " << t << " faces down";
    area += 0.5f * n.z;
  }
  for (int32_t v = 0; v < lod->mesh.num_vertices(); ++v) {
    EXPECT_EQ(lod->mesh.positions[3 * v + 2], 0.0f);
    for (int a = 0; a < 2; ++a) {
      lo[a] = std::min(lo[a], lod->mesh.positions[3 * v + a]);
      hi[a] = std::max(hi[a], lod->mesh.positions[3 * v + a]);
    }
  }
  EXPECT_NEAR(area, 1.0f, 1e-4f);
  EXPECT_EQ(lo[0], 0.0f);
  EXPECT_EQ(lo[1], 0.0f);
  EXPECT_EQ(hi[0], 1.0f);
  EXPECT_EQ(hi[1], 1.0f);
}

TEST(MeshSimplifyTest, AMeshWithinTheBudgetComesBackAsItWas) {
  const TriangleMesh full = Icosphere(2, kRadius);  // 320 triangles
  for (const int64_t budget : {int64_t{320}, int64_t{100000}}) {
    const absl::StatusOr<SimplifiedMesh> same = SimplifyMesh(full, budget);
    ASSERT_TRUE(same.ok()) << same.status();
    EXPECT_EQ(same->mesh.positions, full.positions);
    EXPECT_EQ(same->mesh.normals, full.normals);
    EXPECT_EQ(same->mesh.colors, full.colors);
    EXPECT_EQ(same->mesh.triangles, full.triangles);
    EXPECT_EQ(same->error_m, 0.0);
  }
}

TEST(MeshSimplifyTest, ABudgetTheCollapsesCannotReachIsReachedByClustering) {
  // The "up" triangles of a triangular lattice: no two share an edge, so every inner vertex has
  // three pairs of open edges and may not move. Edge collapses can take little of it; vertex
  // clustering takes the rest.
  constexpr int kSide = 40;
  TriangleMesh lattice;
  for (int j = 0; j <= kSide; ++j) {
    for (int i = 0; i <= kSide; ++i) {
      lattice.positions.insert(lattice.positions.end(),
                               {0.01f * (i + 0.5f * j), 0.01f * 0.8660254f * j, 0.0f});
      lattice.normals.insert(lattice.normals.end(), {0.0f, 0.0f, 1.0f});
      lattice.colors.insert(lattice.colors.end(), {1, 2, 3});
    }
  }
  auto at = [](int i, int j) { return static_cast<int32_t>(j * (kSide + 1) + i); };
  for (int j = 0; j < kSide; ++j) {
    for (int i = 0; i + j < kSide; ++i) {
      lattice.triangles.insert(lattice.triangles.end(), {at(i, j), at(i + 1, j), at(i, j + 1)});
    }
  }
  const int64_t budget = lattice.num_triangles() / 10;
  const absl::StatusOr<SimplifiedMesh> lod = SimplifyMesh(lattice, budget);
  ASSERT_TRUE(lod.ok()) << lod.status();
  EXPECT_LE(lod->mesh.num_triangles(), budget);
  EXPECT_GT(lod->mesh.num_triangles(), 0);
  EXPECT_FALSE(lod->topology_kept);
  ExpectCompactAndNonDegenerate(lod->mesh);
  ExpectVerticesAreInputVertices(lattice, lod->mesh);
}

TEST(MeshSimplifyTest, TheSameInputGivesTheSameLevelOfDetail) {
  const TriangleMesh full = Icosphere(4, kRadius);
  const absl::StatusOr<SimplifiedMesh> a = SimplifyMesh(full, 700);
  const absl::StatusOr<SimplifiedMesh> b = SimplifyMesh(full, 700);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->mesh.positions, b->mesh.positions);
  EXPECT_EQ(a->mesh.triangles, b->mesh.triangles);
}

TEST(MeshSimplifyTest, BadInputIsInvalidAndCancellingStops) {
  const TriangleMesh full = Icosphere(2, kRadius);
  for (const int64_t budget : {int64_t{0}, int64_t{-5}}) {
    const absl::StatusOr<SimplifiedMesh> r = SimplifyMesh(full, budget);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << r.status();
    EXPECT_NE(r.status().message().find("target_triangles"), std::string::npos);
  }
  TriangleMesh broken = full;
  broken.triangles[7] = static_cast<int32_t>(full.num_vertices());
  EXPECT_EQ(SimplifyMesh(broken, 10).status().code(), absl::StatusCode::kInvalidArgument);
  broken = full;
  broken.colors.pop_back();
  EXPECT_EQ(SimplifyMesh(broken, 10).status().code(), absl::StatusCode::kInvalidArgument);
  const absl::StatusOr<SimplifiedMesh> cancelled = SimplifyMesh(full, 10, [] { return true; });
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled) << cancelled.status();
}

}  // namespace mesh_simplify_test
}  // namespace plx

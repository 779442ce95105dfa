// Marching cubes on analytic fields written into a brick grid: a sphere (closed, watertight,
// within half a voxel of the true surface, normals and winding outward), a plane cut off where
// the stored bricks end (no wall there: unstored space is unknown, not empty), colours, the
// unobserved-surface and small-component filters, options and their errors.
#include "core/mesh/iso_surface.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/math/spherical_harmonics.h"
#include "tests/mesh_checks.h"

namespace plx {
namespace {

constexpr float kVoxel = 0.05f;
constexpr float kIso = 25.0f;
// Density falls by this per metre across the surface: 10/m per voxel, so the density stays
// positive for 2.5 voxels outside the surface and the field is linear where the mesh samples
// it. (Maps clamp density at 0 closer to their surfaces; then linear interpolation between a
// clamped and an unclamped end errs by up to half a voxel, which the plane test's walls see.)
constexpr float kSlope = 200.0f;

// A grid with every brick touching [lo, hi] (metres) stored, density and SH DC set per vertex
// from `density` and `color` of the vertex position.
SparseGrid FieldGrid(const float lo[3], const float hi[3],
                     const std::function<float(const float p[3])>& density,
                     const std::function<float(const float p[3])>& gray = nullptr) {
  SparseGrid grid(kVoxel);
  std::vector<BrickCoord> bricks;
  const float brick = kVoxel * kBrickEdge;
  int b0[3], b1[3];
  for (int a = 0; a < 3; ++a) {
    b0[a] = static_cast<int>(std::floor(lo[a] / brick));
    b1[a] = static_cast<int>(std::floor(hi[a] / brick));
  }
  for (int z = b0[2]; z <= b1[2]; ++z) {
    for (int y = b0[1]; y <= b1[1]; ++y) {
      for (int x = b0[0]; x <= b1[0]; ++x) bricks.push_back({x, y, z});
    }
  }
  EXPECT_TRUE(grid.AllocateBricks(bricks).ok());
  for (int64_t slot = 0; slot < grid.num_bricks(); ++slot) {
    float* d = grid.mutable_brick_density(slot);
    float* sh = grid.mutable_brick_sh(slot);
    for (int i = 0; i < kBrickVertices; ++i) {
      const std::array<float, 3> p = grid.VertexPosition(slot, i);
      d[i] = std::max(0.0f, density(p.data()));
      // Grey 0.6, not 0.5: a DC term of exactly 0 would mark the surface unobserved.
      const float g = gray ? gray(p.data()) : 0.6f;
      for (int c = 0; c < 3; ++c) sh[i * kShCoeffCount + c * kShBasisCount] = ShDcForColor(g);
    }
  }
  return grid;
}

constexpr float kCenter[3] = {0.013f, -0.021f, 0.037f};  // off the lattice
constexpr float kRadius = 0.43f;

float SphereDensity(const float p[3]) {
  const float r = std::hypot(p[0] - kCenter[0], p[1] - kCenter[1], p[2] - kCenter[2]);
  return kIso + kSlope * (kRadius - r);
}

SparseGrid SphereGrid() {
  const float lo[3] = {-0.6f, -0.6f, -0.6f}, hi[3] = {0.6f, 0.6f, 0.6f};
  return FieldGrid(lo, hi, SphereDensity);
}

TriangleMesh Extract(const SparseGrid& grid, const MeshOptions& options = {}, int threads = 2) {
  std::unique_ptr<Backend> backend = MakeCpuBackend(threads);
  MeshOptions o = options;
  o.iso_level = kIso;
  absl::StatusOr<TriangleMesh> mesh = ExtractMesh(grid, *backend, o);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : TriangleMesh{};
}

Vec3f Position(const TriangleMesh& m, int64_t v) {
  return {m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]};
}
Vec3f Normal(const TriangleMesh& m, int64_t v) {
  return {m.normals[3 * v], m.normals[3 * v + 1], m.normals[3 * v + 2]};
}
Vec3f FaceNormal(const TriangleMesh& m, int64_t t) {
  const int32_t* f = &m.triangles[3 * t];
  return Cross(Position(m, f[1]) - Position(m, f[0]), Position(m, f[2]) - Position(m, f[0]));
}

TEST(IsoSurfaceTest, SphereIsClosedAndWithinHalfAVoxel) {
  const TriangleMesh mesh = Extract(SphereGrid());
  ASSERT_GT(mesh.num_triangles(), 1000);
  const testing::EdgeUse use = testing::CountEdgeUse(mesh);
  EXPECT_EQ(use.not_twice, 0);
  EXPECT_EQ(use.same_direction, 0);
  // A closed surface of genus 0: V - E + F = 2. Merged vertices make this hold; unmerged ones
  // (a vertex per triangle corner) would not.
  EXPECT_EQ(mesh.num_vertices() - use.edges + mesh.num_triangles(), 2);
  const Vec3f c{kCenter[0], kCenter[1], kCenter[2]};
  double worst = 0.0;
  for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
    const Vec3f d = Position(mesh, v) - c;
    worst = std::max(worst, std::abs(static_cast<double>(Norm(d)) - kRadius));
    // Central differences of a radial field point along the radius up to O(h / r): a few
    // degrees at 8 voxels of radius.
    EXPECT_GT(Dot(Normal(mesh, v), d * (1.0f / Norm(d))), 0.99f) << "vertex " << v;
  }
  // Half a voxel is the bound the issue asks for. Linear interpolation along an edge of a field
  // linear in the distance to the centre misses the sphere by about the sagitta,
  // h^2 / (8 r) = 0.7 mm here.
  EXPECT_LT(worst, 0.5 * kVoxel);
  EXPECT_LT(worst, 0.002);
  for (int64_t t = 0; t < mesh.num_triangles(); ++t) {
    const int32_t v = mesh.triangles[3 * t];
    EXPECT_GT(Dot(FaceNormal(mesh, t), Position(mesh, v) - c), 0.0f) << "triangle " << t;
  }
}

TEST(IsoSurfaceTest, TheSameMeshOnAnyThreadCount) {
  const SparseGrid grid = SphereGrid();
  const TriangleMesh one = Extract(grid, {}, 1);
  const TriangleMesh two = Extract(grid, {}, 2);
  EXPECT_EQ(one.triangles, two.triangles);
  EXPECT_EQ(one.positions, two.positions);
  EXPECT_EQ(one.colors, two.colors);
}

// Solid below z = 0.21 inside a slab of bricks: the mesh is the plane alone, open where the
// stored bricks end (the solid's sides and bottom border unstored space, which is not meshed),
// flat and within half a voxel of the plane, as large as the stored slab.
TEST(IsoSurfaceTest, PlaneEndsWhereTheStoredBricksEnd) {
  constexpr float kPlane = 0.21f;
  const float lo[3] = {0.0f, 0.0f, 0.0f}, hi[3] = {0.7f, 0.3f, 0.3f};
  const SparseGrid grid = FieldGrid(lo, hi, [](const float p[3]) {
    return kIso + kSlope * (kPlane - p[2]);
  });
  const TriangleMesh mesh = Extract(grid);
  ASSERT_GT(mesh.num_triangles(), 0);
  const testing::EdgeUse use = testing::CountEdgeUse(mesh);
  EXPECT_EQ(use.same_direction, 0);
  // Stored vertices span x in [0, 0.75] and y in [0, 0.35] (2 x 1 bricks of 8 vertices), so the
  // plane crosses 15 x 7 cells, each a quad of two triangles; only the rim is open, one
  // triangle edge per rim cell: 2 * (15 + 7).
  EXPECT_EQ(use.not_twice, 2 * (15 + 7));
  double area = 0.0;
  for (int64_t t = 0; t < mesh.num_triangles(); ++t) {
    const Vec3f n = FaceNormal(mesh, t);
    EXPECT_GT(n.z, 0.999f * Norm(n));
    area += 0.5 * Norm(n);
  }
  EXPECT_NEAR(area, 0.75 * 0.35, 1e-4);
  for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
    const Vec3f p = Position(mesh, v);
    EXPECT_NEAR(p.z, kPlane, 1e-4);
    // Away from the rim the gradient is the plane's; at it, central differences see unstored
    // space (read as 0) beside the slab.
    if (p.x > 0.0f && p.x < 0.75f && p.y > 0.0f && p.y < 0.35f) {
      EXPECT_GT(Normal(mesh, v).z, 0.999f);
    }
  }
}

TEST(IsoSurfaceTest, ColoursComeFromTheDcTerm) {
  const float lo[3] = {-0.6f, -0.6f, -0.6f}, hi[3] = {0.6f, 0.6f, 0.6f};
  // Grey level rising with x: each vertex's colour follows its x within the blending error.
  const SparseGrid shaded = FieldGrid(lo, hi, SphereDensity,
                                      [](const float p[3]) { return 0.513f + 0.4f * p[0]; });
  const TriangleMesh mesh = Extract(shaded);
  ASSERT_GT(mesh.num_vertices(), 0);
  for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
    const float expected = (0.513f + 0.4f * Position(mesh, v).x) * 255.0f;
    // The colour blends the two edge ends (at most a voxel apart): 0.4 * 0.05 * 255 = 5.1.
    // (Never exactly grey 0.5 at a vertex, which would read as unobserved.)
    EXPECT_NEAR(mesh.colors[3 * v], expected, 5.5f) << "vertex " << v;
    EXPECT_EQ(mesh.colors[3 * v], mesh.colors[3 * v + 1]);
  }
}

TEST(IsoSurfaceTest, SmallComponentsAreRemovedOnRequest) {
  // The sphere and a small ball (radius 1.5 voxels) far from it.
  const float lo[3] = {-0.6f, -0.6f, -0.6f}, hi[3] = {1.2f, 0.6f, 0.6f};
  const SparseGrid grid = FieldGrid(lo, hi, [](const float p[3]) {
    const float r = std::hypot(p[0] - 0.9f, p[1] - 0.01f, p[2] - 0.02f);
    return std::max(SphereDensity(p), kIso + kSlope * (0.075f - r));
  });
  const TriangleMesh all = Extract(grid);
  MeshOptions o;
  o.min_component_triangles = 200;
  const TriangleMesh cleaned = Extract(grid, o);
  const TriangleMesh sphere = Extract(SphereGrid());
  EXPECT_GT(all.num_triangles(), sphere.num_triangles());
  EXPECT_EQ(cleaned.num_triangles(), sphere.num_triangles());
  EXPECT_EQ(cleaned.num_vertices(), sphere.num_vertices());
  for (int64_t v = 0; v < cleaned.num_vertices(); ++v) EXPECT_LT(Position(cleaned, v).x, 0.6f);
  EXPECT_EQ(testing::CountEdgeUse(cleaned).not_twice, 0);
}

// A surface whose SH are all zero was never seen (IsoVertex::observed): dropped unless asked for.
TEST(IsoSurfaceTest, UnobservedSurfacesAreDroppedUnlessKept) {
  const float lo[3] = {-0.6f, -0.6f, -0.6f}, hi[3] = {0.6f, 0.6f, 0.6f};
  const SparseGrid grid = FieldGrid(lo, hi, SphereDensity, [](const float p[3]) {
    return p[0] > 0.0f ? 0.5f : 0.7f;  // DC 0 (and so all SH 0) on the +x half
  });
  const TriangleMesh half = Extract(grid);
  MeshOptions o;
  o.keep_unobserved = true;
  const TriangleMesh whole = Extract(grid, o);
  EXPECT_EQ(whole.num_triangles(), Extract(SphereGrid()).num_triangles());
  EXPECT_GT(half.num_triangles(), whole.num_triangles() * 4 / 10);
  EXPECT_LT(half.num_triangles(), whole.num_triangles() * 6 / 10);
  // What is left is the seen half, plus the triangles with a corner next to it.
  for (int64_t v = 0; v < half.num_vertices(); ++v) EXPECT_LT(Position(half, v).x, kVoxel);
}

TEST(IsoSurfaceTest, BadOptionsCancellationAndTheTriangleCap) {
  const SparseGrid grid = SphereGrid();
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  MeshOptions o;
  o.iso_level = 0.0f;
  absl::StatusOr<TriangleMesh> mesh = ExtractMesh(grid, *backend, o);
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(mesh.status().message().find("iso_level"), std::string::npos) << mesh.status();
  o = {};
  o.iso_level = std::nanf("");
  EXPECT_EQ(ExtractMesh(grid, *backend, o).status().code(), absl::StatusCode::kInvalidArgument);
  o = {};
  o.min_component_triangles = -1;
  mesh = ExtractMesh(grid, *backend, o);
  EXPECT_NE(mesh.status().message().find("min_component_triangles"), std::string::npos);
  o = {};
  o.max_triangles = 0;
  mesh = ExtractMesh(grid, *backend, o);
  EXPECT_NE(mesh.status().message().find("max_triangles"), std::string::npos);

  o = {};
  o.iso_level = kIso;
  o.max_triangles = 100;
  mesh = ExtractMesh(grid, *backend, o);
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kResourceExhausted) << mesh.status();

  mesh = ExtractMesh(grid, *backend, MeshOptions{}, [] { return true; });
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kCancelled);

  const SparseGrid empty(kVoxel);
  mesh = ExtractMesh(empty, *backend, MeshOptions{});
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->num_triangles(), 0);
}

}  // namespace
}  // namespace plx

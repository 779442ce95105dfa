// The mesh of a box of the map (MeshOptions::region): the triangles of the cells whose centres
// the box holds, kept whole and the same as the full mesh's; two boxes sharing a face split the
// full mesh between them; only the box's bricks are visited; an empty box region is an empty
// mesh, and a box that is not finite or has min >= max is refused naming the region.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/math/spherical_harmonics.h"
#include "core/mesh/iso_surface.h"

namespace plx {
namespace mesh_region_test {

constexpr float kVoxel = 0.05f;
constexpr float kIso = 25.0f;
constexpr float kSlope = 200.0f;  // density per metre across the surface (as iso_surface_test)

// Every brick touching [lo, hi] stored; density `density(p)` (clamped at 0), grey and seen.
SparseGrid FieldGrid(const std::array<float, 3>& lo, const std::array<float, 3>& hi,
                     float (*density)(const std::array<float, 3>&)) {
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
      d[i] = std::max(0.0f, density(grid.VertexPosition(slot, i)));
      for (int c = 0; c < 3; ++c) sh[i * kShCoeffCount + c * kShBasisCount] = ShDcForColor(0.6f);
    }
  }
  return grid;
}

float SphereDensity(const std::array<float, 3>& p) {
  const float r = std::hypot(p[0] - 0.013f, p[1] + 0.021f, p[2] - 0.037f);
  return kIso + kSlope * (0.43f - r);
}

SparseGrid SphereGrid() {
  return FieldGrid({-0.6f, -0.6f, -0.6f}, {0.6f, 0.6f, 0.6f}, SphereDensity);
}

absl::StatusOr<TriangleMesh> Extract(const SparseGrid& grid, Backend& backend,
                                     const std::optional<AxisBox>& region) {
  MeshOptions o;
  o.iso_level = kIso;
  o.region = region;
  return ExtractMesh(grid, backend, o);
}

using Corner = std::array<float, 3>;
using Triangle = std::array<Corner, 3>;

Corner Position(const TriangleMesh& m, int32_t v) {
  return {m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]};
}

// Each triangle as its corners' positions, rotated to start at the smallest (the winding kept),
// sorted: two meshes with the same triangles at the same places give the same list.
std::vector<Triangle> Triangles(const TriangleMesh& m) {
  std::vector<Triangle> out;
  for (int64_t t = 0; t < m.num_triangles(); ++t) {
    Triangle tri;
    for (int c = 0; c < 3; ++c) tri[c] = Position(m, m.triangles[3 * t + c]);
    std::rotate(tri.begin(), std::min_element(tri.begin(), tri.end()), tri.end());
    out.push_back(tri);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Runs the CPU backend's marching cubes, counting the cells the triangle counts were asked of.
class CellCountingBackend final : public Backend {
 public:
  std::string name() const override { return "cell-counting cpu"; }
  int parallelism() const override { return cpu_->parallelism(); }
  int64_t cells_counted = 0;

 protected:
  absl::Status Launch(const KernelArgs& args) override {
    return std::visit([this](const auto& a) { return Forward(a); }, args);
  }

 private:
  absl::Status Forward(const CountIsoTrianglesArgs& a) {
    cells_counted += a.count;
    return cpu_->CountIsoTriangles(a.grid, a.first_vertex, a.count, a.params, a.triangles,
                                   a.bricks);
  }
  absl::Status Forward(const EmitIsoTrianglesArgs& a) {
    return cpu_->EmitIsoTriangles(a.grid, a.first_vertex, a.count, a.params, a.first_triangle,
                                  a.edge_keys, a.bricks);
  }
  absl::Status Forward(const ComputeIsoVerticesArgs& a) {
    return cpu_->ComputeIsoVertices(a.grid, a.edge_keys, a.count, a.params, a.positions,
                                    a.normals, a.colors, a.observed);
  }
  template <typename Args>
  absl::Status Forward(const Args&) {
    return absl::UnimplementedError("ExtractMesh launches marching cubes only");
  }

  std::unique_ptr<Backend> cpu_ = MakeCpuBackend(2);
};

TEST(MeshRegionTest, TwoBoxesSharingAFaceSplitTheFullMeshWithItsVerticesUnchanged) {
  const SparseGrid grid = SphereGrid();
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  const absl::StatusOr<TriangleMesh> full = Extract(grid, *backend, std::nullopt);
  ASSERT_TRUE(full.ok()) << full.status();
  // Off the lattice, through the middle of the sphere.
  constexpr double kSplit = 0.0321;
  const AxisBox lower{{-1.0, -1.0, -1.0}, {kSplit, 1.0, 1.0}};
  const AxisBox upper{{kSplit, -1.0, -1.0}, {1.0, 1.0, 1.0}};
  const absl::StatusOr<TriangleMesh> low = Extract(grid, *backend, lower);
  const absl::StatusOr<TriangleMesh> high = Extract(grid, *backend, upper);
  ASSERT_TRUE(low.ok()) << low.status();
  ASSERT_TRUE(high.ok()) << high.status();
  EXPECT_GT(low->num_triangles(), full->num_triangles() / 3);
  EXPECT_GT(high->num_triangles(), full->num_triangles() / 3);
  EXPECT_EQ(low->num_triangles() + high->num_triangles(), full->num_triangles());
  std::vector<Triangle> both = Triangles(*low);
  const std::vector<Triangle> upper_triangles = Triangles(*high);
  both.insert(both.end(), upper_triangles.begin(), upper_triangles.end());
  std::sort(both.begin(), both.end());
  EXPECT_TRUE(both == Triangles(*full)) << "the halves are not the full mesh's triangles";

  // Kept whole: every triangle lies in its cell, so at most half a voxel past its box.
  const double slack = 0.5 * kVoxel + 1e-6;
  for (int32_t v = 0; v < low->num_vertices(); ++v) {
    EXPECT_LE(Position(*low, v)[0], kSplit + slack);
  }
  for (int32_t v = 0; v < high->num_vertices(); ++v) {
    EXPECT_GE(Position(*high, v)[0], kSplit - slack);
  }
  // Each vertex is the full mesh's: the same normal and colour at the same place.
  std::map<Corner, std::pair<Corner, Corner>> attributes;
  for (int32_t v = 0; v < full->num_vertices(); ++v) {
    attributes[Position(*full, v)] = {
        {full->normals[3 * v], full->normals[3 * v + 1], full->normals[3 * v + 2]},
        {full->colors[3 * v] * 1.0f, full->colors[3 * v + 1] * 1.0f,
         full->colors[3 * v + 2] * 1.0f}};
  }
  for (const TriangleMesh* half : {&*low, &*high}) {
    for (int32_t v = 0; v < half->num_vertices(); ++v) {
      const auto it = attributes.find(Position(*half, v));
      ASSERT_NE(it, attributes.end()) << "a vertex the full mesh does not have";
      EXPECT_EQ(it->second.first,
                (Corner{half->normals[3 * v], half->normals[3 * v + 1], half->normals[3 * v + 2]}));
      EXPECT_EQ(it->second.second, (Corner{half->colors[3 * v] * 1.0f,
                                           half->colors[3 * v + 1] * 1.0f,
                                           half->colors[3 * v + 2] * 1.0f}));
    }
  }
}

// A plane through a slab of 6 x 6 bricks; a box inside one brick's cells: only that brick is
// visited, not the 36.
TEST(MeshRegionTest, OnlyTheBricksHoldingTheBoxsCellsAreVisited) {
  const SparseGrid grid = FieldGrid({0.0f, 0.0f, 0.0f}, {2.0f, 2.0f, 0.3f},
                                    [](const std::array<float, 3>& p) {
                                      return kIso + kSlope * (0.21f - p[2]);
                                    });
  ASSERT_EQ(grid.num_bricks(), 36);
  CellCountingBackend counting;
  const absl::StatusOr<TriangleMesh> full = Extract(grid, counting, std::nullopt);
  ASSERT_TRUE(full.ok()) << full.status();
  EXPECT_EQ(counting.cells_counted, 36 * kBrickVertices);

  counting.cells_counted = 0;
  // World bricks are 0.4 m; cells with centres in [0.45, 0.75) are cells 9..14 of brick 1.
  const AxisBox box{{0.45, 0.45, -1.0}, {0.75, 0.75, 1.0}};
  const absl::StatusOr<TriangleMesh> region = Extract(grid, counting, box);
  ASSERT_TRUE(region.ok()) << region.status();
  EXPECT_EQ(counting.cells_counted, kBrickVertices);
  // 6 x 6 cells crossed by the plane, two triangles each.
  EXPECT_EQ(region->num_triangles(), 2 * 6 * 6);
  for (int32_t v = 0; v < region->num_vertices(); ++v) {
    for (int a = 0; a < 2; ++a) {
      EXPECT_GE(Position(*region, v)[a], 0.45f - 1e-5f);
      EXPECT_LE(Position(*region, v)[a], 0.75f + 1e-5f);
    }
  }
}

TEST(MeshRegionTest, AnEmptyBoxRegionIsAnEmptyMeshAndABadBoxIsRefused) {
  const SparseGrid grid = SphereGrid();
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  // Far from every brick, and inside the sphere's solid (bricks, no surface).
  for (const AxisBox& nothing : {AxisBox{{5.0, 5.0, 5.0}, {6.0, 6.0, 6.0}},
                                 AxisBox{{-0.1, -0.1, -0.1}, {0.1, 0.1, 0.1}}}) {
    const absl::StatusOr<TriangleMesh> mesh = Extract(grid, *backend, nothing);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_EQ(mesh->num_triangles(), 0);
    EXPECT_EQ(mesh->num_vertices(), 0);
  }
  // Larger than any map: the whole mesh.
  const absl::StatusOr<TriangleMesh> all =
      Extract(grid, *backend, AxisBox{{-1e30, -1e30, -1e30}, {1e30, 1e30, 1e30}});
  const absl::StatusOr<TriangleMesh> full = Extract(grid, *backend, std::nullopt);
  ASSERT_TRUE(all.ok()) << all.status();
  ASSERT_TRUE(full.ok()) << full.status();
  EXPECT_EQ(all->triangles, full->triangles);

  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  constexpr double inf = std::numeric_limits<double>::infinity();
  for (const AxisBox& bad : {AxisBox{{0.0, 0.0, 0.0}, {1.0, 0.0, 1.0}},
                             AxisBox{{0.0, 0.0, 2.0}, {1.0, 1.0, 1.0}},
                             AxisBox{{nan, 0.0, 0.0}, {1.0, 1.0, 1.0}},
                             AxisBox{{0.0, 0.0, 0.0}, {1.0, inf, 1.0}}}) {
    const absl::StatusOr<TriangleMesh> mesh = Extract(grid, *backend, bad);
    EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument) << mesh.status();
    EXPECT_EQ(mesh.status().message().rfind("region: ", 0), 0u) << mesh.status();
  }
}

}  // namespace mesh_region_test
}  // namespace plx

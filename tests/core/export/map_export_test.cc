// ExportMap (core/export/map_export.h), the file `plenox export` and the daemon's Export both
// make: for points it is the surface point export at the spec's density, for a mesh the
// marching-cubes mesh with the spec's options encoded with the map's source as PLY or binary
// glTF (the same mesh either way), simplified to the spec's triangle budget when it names one,
// and a cancelled or refused export makes no file.
#include "core/export/map_export.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/formats/glb_mesh.h"
#include "core/formats/ply_mesh.h"
#include "core/math/spherical_harmonics.h"
#include "tests/glb_reader.h"
#include "tests/grid_fill.h"
#include "tests/ply_mesh_reader.h"

namespace plx {
namespace {

// Two bricks whose vertices alternate between `dense` and 0: every dense vertex is on the
// surface, and every cell has a crossing at an iso-level below `dense`.
PlenoxelMap AlternatingMap(float dense) {
  PlenoxelMap map(0.05f);
  map.source = "two alternating bricks";
  EXPECT_TRUE(map.grid.AllocateBricks({{0, 0, 0}, {1, 0, 0}}).ok());
  int i = 0;
  testing::FillDensity(map.grid, [&] { return (i++ % 2) ? dense : 0.0f; });
  return map;
}

// A ball of radius 0.3 m at 2 cm voxels: density falling 500/m across its surface at the
// default iso-level (50/m), grey and seen (non-zero SH): about 8500 triangles of smooth surface.
PlenoxelMap BallMap() {
  constexpr float kVoxel = 0.02f, kRadius = 0.3f;
  PlenoxelMap map(kVoxel);
  map.source = "a ball";
  std::vector<BrickCoord> bricks;
  for (int z = -3; z < 3; ++z) {
    for (int y = -3; y < 3; ++y) {
      for (int x = -3; x < 3; ++x) bricks.push_back({x, y, z});
    }
  }
  EXPECT_TRUE(map.grid.AllocateBricks(bricks).ok());
  for (int64_t slot = 0; slot < map.grid.num_bricks(); ++slot) {
    float* d = map.grid.mutable_brick_density(slot);
    float* sh = map.grid.mutable_brick_sh(slot);
    for (int i = 0; i < kBrickVertices; ++i) {
      const std::array<float, 3> p = map.grid.VertexPosition(slot, i);
      const float r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
      d[i] = std::max(0.0f, kDefaultMeshIsoLevel + 500.0f * (kRadius - r));
      for (int c = 0; c < 3; ++c) sh[i * kShCoeffCount + c * kShBasisCount] = ShDcForColor(0.6f);
    }
  }
  return map;
}

TEST(MapExportTest, PointsAreTheSurfacePointsAtTheSpecsDensity) {
  const PlenoxelMap map = AlternatingMap(3.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.min_density = 2.0f;
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();
  const absl::StatusOr<PlyExport> direct = ExportSurfacePointsPly(map, 2.0f);
  ASSERT_TRUE(direct.ok()) << direct.status();
  EXPECT_EQ(ply->vertices, 512);
  EXPECT_EQ(ply->faces, 0);
  EXPECT_EQ(ply->bytes, direct->bytes);

  // The default threshold (5/m) is above every vertex of this map.
  const absl::StatusOr<MapExport> by_default =
      ExportMap(ExportSpec(), map, MapKeyframes(), *backend);
  ASSERT_TRUE(by_default.ok()) << by_default.status();
  EXPECT_EQ(by_default->vertices, 0);
}

TEST(MapExportTest, AMeshIsTheEnginesMeshWithTheMapsSource) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_options.iso_level = 5.0f;
  spec.mesh_options.keep_unobserved = true;  // the SH are 0: no view saw anything
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();

  const absl::StatusOr<TriangleMesh> mesh = ExtractMesh(map.grid, *backend, spec.mesh_options);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  const absl::StatusOr<PlyMesh> direct = EncodePlyMesh(*mesh, map.source);
  ASSERT_TRUE(direct.ok()) << direct.status();
  EXPECT_GT(ply->faces, 0);
  EXPECT_EQ(ply->vertices, direct->vertices);
  EXPECT_EQ(ply->faces, direct->faces);
  EXPECT_EQ(ply->bytes, direct->bytes);
  EXPECT_NE(ply->bytes.find("two alternating bricks"), std::string::npos);

  // The options are the spec's: without keep_unobserved nothing is left.
  spec.mesh_options.keep_unobserved = false;
  const absl::StatusOr<MapExport> observed_only = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(observed_only.ok()) << observed_only.status();
  EXPECT_EQ(observed_only->faces, 0);
}

TEST(MapExportTest, GlbIsTheSameMeshAsPly) {
  const PlenoxelMap map = BallMap();
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  ExportSpec spec;
  spec.mesh = true;
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();
  spec.mesh_format = MeshFileFormat::kGlb;
  const absl::StatusOr<MapExport> glb = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(glb.ok()) << glb.status();
  EXPECT_GT(glb->faces, 5000);
  EXPECT_EQ(glb->faces, ply->faces);
  EXPECT_EQ(glb->full_faces, glb->faces);
  EXPECT_EQ(glb->lod_error_m, 0.0);
  const absl::StatusOr<testing::PlyMeshFile> from_ply = testing::ReadPlyMesh(ply->bytes);
  const absl::StatusOr<testing::GlbFile> from_glb = testing::ReadGlb(glb->bytes);
  ASSERT_TRUE(from_ply.ok()) << from_ply.status();
  ASSERT_TRUE(from_glb.ok()) << from_glb.status();
  EXPECT_EQ(from_glb->mesh.positions, from_ply->mesh.positions);
  EXPECT_EQ(from_glb->mesh.colors, from_ply->mesh.colors);
  EXPECT_EQ(from_glb->mesh.triangles, from_ply->mesh.triangles);
  EXPECT_EQ(from_glb->json["asset"]["extras"]["plenoxd"]["source"], "a ball");
  EXPECT_EQ(from_glb->index_component_type, 5123);
}

TEST(MapExportTest, ALevelOfDetailKeepsToTheBudgetInEitherFormat) {
  const PlenoxelMap map = BallMap();
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  ExportSpec spec;
  spec.mesh = true;
  const absl::StatusOr<MapExport> full = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(full.ok()) << full.status();
  spec.lod_triangles = full->faces / 10;
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_LE(ply->faces, spec.lod_triangles);
  EXPECT_GT(ply->faces, spec.lod_triangles * 9 / 10);
  EXPECT_EQ(ply->full_faces, full->faces);
  // A 2 cm-voxel ball at a tenth of its triangles (850) moves by less than half a voxel (the
  // reported error sums the halving passes' errors, so it is the generous side).
  EXPECT_GT(ply->lod_error_m, 0.0);
  EXPECT_LT(ply->lod_error_m, 0.01);
  spec.mesh_format = MeshFileFormat::kGlb;
  const absl::StatusOr<MapExport> glb = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(glb.ok()) << glb.status();
  EXPECT_EQ(glb->faces, ply->faces);
  EXPECT_EQ(glb->lod_error_m, ply->lod_error_m);
  const absl::StatusOr<testing::GlbFile> file = testing::ReadGlb(glb->bytes);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->mesh.num_triangles(), glb->faces);
  const nlohmann::json& extras = file->json["asset"]["extras"]["plenoxd"];
  EXPECT_EQ(extras["full_triangles"], full->faces);
  EXPECT_EQ(extras["lod_error_m"], glb->lod_error_m);
  // Every vertex still lies on the ball's surface (a LOD keeps input vertices).
  for (int64_t v = 0; v < file->mesh.num_vertices(); ++v) {
    const float* p = &file->mesh.positions[3 * v];
    ASSERT_NEAR(std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]), 0.3f, 0.01f);
  }
  // A budget at or above the mesh's size is the full mesh.
  spec.lod_triangles = full->faces;
  const absl::StatusOr<MapExport> same = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(same.ok()) << same.status();
  EXPECT_EQ(same->faces, full->faces);
  EXPECT_EQ(same->lod_error_m, 0.0);
}

// The ball split at x = 0 (a lattice plane at its 2 cm voxels): the box's half, about half the
// triangles, in either format and at a level of detail, and the file says which box it holds.
TEST(MapExportTest, ARegionIsTheBoxsHalfOfTheMeshAndTheFileRecordsTheBox) {
  const PlenoxelMap map = BallMap();
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_format = MeshFileFormat::kGlb;
  const absl::StatusOr<MapExport> full = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(full.ok()) << full.status();
  const AxisBox half{{-1.0, -1.0, -1.0}, {0.0, 1.0, 1.0}};
  spec.mesh_options.region = half;
  const absl::StatusOr<MapExport> glb = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(glb.ok()) << glb.status();
  EXPECT_NEAR(static_cast<double>(glb->faces) / full->faces, 0.5, 0.02);
  EXPECT_EQ(glb->full_faces, glb->faces);
  const absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(glb->bytes);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->region, half);
  const absl::StatusOr<testing::GlbFile> file = testing::ReadGlb(glb->bytes);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->mesh.num_triangles(), glb->faces);
  // Cells with centres below x = 0 end at x = 0: no vertex past the box.
  ASSERT_EQ(file->position_max.size(), 3u);
  EXPECT_LE(file->position_max[0], 1e-6);
  EXPECT_LT(file->position_min[0], -0.29);
  const absl::StatusOr<GlbMeshInfo> whole = ReadGlbMeshInfo(full->bytes);
  ASSERT_TRUE(whole.ok()) << whole.status();
  EXPECT_FALSE(whole->region.has_value());

  spec.mesh_format = MeshFileFormat::kPly;
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_EQ(ply->faces, glb->faces);
  EXPECT_NE(ply->bytes.find(PlyRegionComment(half)), std::string::npos);
  EXPECT_EQ(PlyRegionComment(half), "comment plenoxd region: -1 -1 -1 0 1 1\n");
  const absl::StatusOr<testing::PlyMeshFile> read = testing::ReadPlyMesh(ply->bytes);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->mesh.triangles, file->mesh.triangles);

  // A level of detail of the region: the region's mesh is the full one it simplifies.
  spec.lod_triangles = glb->faces / 5;
  const absl::StatusOr<MapExport> lod = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(lod.ok()) << lod.status();
  EXPECT_LE(lod->faces, spec.lod_triangles);
  EXPECT_EQ(lod->full_faces, glb->faces);

  // A box with nothing mapped in it: a valid, empty file that still names its box.
  spec.lod_triangles = 0;
  spec.mesh_format = MeshFileFormat::kGlb;
  spec.mesh_options.region = AxisBox{{2.0, 2.0, 2.0}, {3.0, 3.0, 3.0}};
  const absl::StatusOr<MapExport> empty = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(empty.ok()) << empty.status();
  EXPECT_EQ(empty->faces, 0);
  const absl::StatusOr<GlbMeshInfo> nothing = ReadGlbMeshInfo(empty->bytes);
  ASSERT_TRUE(nothing.ok()) << nothing.status();
  EXPECT_EQ(nothing->triangles, 0);
  EXPECT_EQ(nothing->region, spec.mesh_options.region);
}

TEST(MapExportTest, SpecsCoreRefusesAreRefusedNamingTheField) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  struct Case {
    ExportSpec spec;
    const char* field;
  };
  std::vector<Case> cases(8);
  cases[6].spec.mesh_surface = MeshSurface::kDensity;  // of points
  cases[6].field = "mesh_surface: applies to meshes only";
  cases[7].spec.mesh = true;
  cases[7].spec.mesh_surface = static_cast<MeshSurface>(9);
  cases[7].field = "mesh_surface: unknown";
  cases[4].spec.mesh_options.region = AxisBox{{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}};  // of points
  cases[4].field = "region: applies to meshes only";
  cases[5].spec.mesh = true;
  cases[5].spec.mesh_options.region = AxisBox{{0.0, 0.0, 0.0}, {1.0, 1.0, 0.0}};  // flat
  cases[5].field = "region: min must be below max";
  cases[0].spec.mesh_format = MeshFileFormat::kGlb;  // points as glTF
  cases[0].field = "mesh_format";
  cases[1].spec.lod_triangles = 10;  // points at a level of detail
  cases[1].field = "lod_triangles";
  cases[2].spec.mesh = true;
  cases[2].spec.lod_triangles = -1;
  cases[2].field = "lod_triangles";
  cases[3].spec.mesh = true;
  cases[3].spec.lod_triangles = kMaxLodTriangles + 1;
  cases[3].field = "lod_triangles";
  for (const Case& c : cases) {
    const absl::StatusOr<MapExport> r = ExportMap(c.spec, map, MapKeyframes(), *backend);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(r.status().message().find(c.field), std::string::npos) << r.status();
  }
}

TEST(MapExportTest, ACancelledExportOfEitherFormIsCancelled) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  for (const bool mesh : {false, true}) {
    SCOPED_TRACE(mesh ? "mesh" : "points");
    ExportSpec spec;
    spec.mesh = mesh;
    const absl::StatusOr<MapExport> ply =
        ExportMap(spec, map, MapKeyframes(), *backend, [] { return true; });
    EXPECT_EQ(ply.status().code(), absl::StatusCode::kCancelled) << ply.status();
  }
}

// The observed surface needs the map's keyframes: asked for without them it is refused, and
// the automatic choice falls back to the density's surface.
TEST(MapExportTest, TheObservedSurfaceWithoutKeyframesIsAFailedPrecondition) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_surface = MeshSurface::kObserved;
  const absl::StatusOr<MapExport> observed = ExportMap(spec, map, MapKeyframes(), *backend);
  EXPECT_EQ(observed.status().code(), absl::StatusCode::kFailedPrecondition)
      << observed.status();
  EXPECT_NE(observed.status().message().find("no keyframes"), std::string::npos);
  spec.mesh_surface = MeshSurface::kAuto;
  const absl::StatusOr<MapExport> automatic = ExportMap(spec, map, MapKeyframes(), *backend);
  spec.mesh_surface = MeshSurface::kDensity;
  const absl::StatusOr<MapExport> density = ExportMap(spec, map, MapKeyframes(), *backend);
  ASSERT_TRUE(automatic.ok()) << automatic.status();
  ASSERT_TRUE(density.ok()) << density.status();
  EXPECT_EQ(automatic->bytes, density->bytes);
  EXPECT_EQ(MeshSurfaceFromName("observed").value(), MeshSurface::kObserved);
  EXPECT_EQ(MeshSurfaceFromName("seen").status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(MapExportTest, MeshOptionsCoreRefusesAreRefused) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_options.max_triangles = 0;
  const absl::StatusOr<MapExport> ply = ExportMap(spec, map, MapKeyframes(), *backend);
  EXPECT_EQ(ply.status().code(), absl::StatusCode::kInvalidArgument) << ply.status();
  EXPECT_NE(ply.status().message().find("max_triangles"), std::string::npos) << ply.status();
}

}  // namespace
}  // namespace plx

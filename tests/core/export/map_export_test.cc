// ExportMapPly (core/export/map_export.h), the PLY file `plenox export` and the daemon's Export
// both make: for points it is the surface point export at the spec's density, for a mesh the
// marching-cubes mesh with the spec's options encoded with the map's source, and a cancelled or
// refused export makes no file.
#include "core/export/map_export.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/formats/ply_mesh.h"
#include "tests/grid_fill.h"

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

TEST(MapExportTest, PointsAreTheSurfacePointsAtTheSpecsDensity) {
  const PlenoxelMap map = AlternatingMap(3.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.min_density = 2.0f;
  const absl::StatusOr<MapPly> ply = ExportMapPly(spec, map, *backend);
  ASSERT_TRUE(ply.ok()) << ply.status();
  const absl::StatusOr<PlyExport> direct = ExportSurfacePointsPly(map, 2.0f);
  ASSERT_TRUE(direct.ok()) << direct.status();
  EXPECT_EQ(ply->vertices, 512);
  EXPECT_EQ(ply->faces, 0);
  EXPECT_EQ(ply->bytes, direct->bytes);

  // The default threshold (5/m) is above every vertex of this map.
  const absl::StatusOr<MapPly> by_default = ExportMapPly(ExportSpec(), map, *backend);
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
  const absl::StatusOr<MapPly> ply = ExportMapPly(spec, map, *backend);
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
  const absl::StatusOr<MapPly> observed_only = ExportMapPly(spec, map, *backend);
  ASSERT_TRUE(observed_only.ok()) << observed_only.status();
  EXPECT_EQ(observed_only->faces, 0);
}

TEST(MapExportTest, ACancelledExportOfEitherFormIsCancelled) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  for (const bool mesh : {false, true}) {
    SCOPED_TRACE(mesh ? "mesh" : "points");
    ExportSpec spec;
    spec.mesh = mesh;
    const absl::StatusOr<MapPly> ply = ExportMapPly(spec, map, *backend, [] { return true; });
    EXPECT_EQ(ply.status().code(), absl::StatusCode::kCancelled) << ply.status();
  }
}

TEST(MapExportTest, MeshOptionsCoreRefusesAreRefused) {
  const PlenoxelMap map = AlternatingMap(10.0f);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_options.max_triangles = 0;
  const absl::StatusOr<MapPly> ply = ExportMapPly(spec, map, *backend);
  EXPECT_EQ(ply.status().code(), absl::StatusCode::kInvalidArgument) << ply.status();
  EXPECT_NE(ply.status().message().find("max_triangles"), std::string::npos) << ply.status();
}

}  // namespace
}  // namespace plx

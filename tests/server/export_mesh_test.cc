// Export with format MESH: the daemon's mesh is byte for byte the one the engine makes of the
// same map in-process (the worker runs the same extraction), reads back as a valid mesh, and bad
// mesh options name their field.
#include <gtest/gtest.h>

#include <cmath>

#include "core/cpu/cpu_backend.h"
#include "core/formats/map_file.h"
#include "core/formats/ply_mesh.h"
#include "core/mesh/iso_surface.h"
#include "core/mesh/observed_surface.h"
#include "tests/ply_mesh_reader.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

class ExportMeshTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    absl::StatusOr<std::unique_ptr<TestDaemon>> d = StartWithMaps({"room"});
    ASSERT_TRUE(d.ok()) << d.status();
    daemon_ = d->release();
  }
  static void TearDownTestSuite() {
    delete daemon_;
    daemon_ = nullptr;
  }
  static pb::ExportRequest MeshRequest() {
    pb::ExportRequest r;
    r.set_map("room");
    r.set_format(pb::EXPORT_FORMAT_MESH);
    return r;
  }
  static grpc::Status Run(const pb::ExportRequest& r, std::string* bytes) {
    return Export(*daemon_->stub, r, bytes);
  }
  static TestDaemon* daemon_;
};
TestDaemon* ExportMeshTest::daemon_ = nullptr;

TEST_F(ExportMeshTest, TheDaemonsMeshIsTheEnginesMesh) {
  pb::ExportRequest request = MeshRequest();
  request.set_min_component_triangles(20);
  std::string bytes;
  const grpc::Status s = Run(request, &bytes);
  ASSERT_TRUE(s.ok()) << Describe(s);

  // The map the daemon integrated keeps its keyframes, so the default is their observed
  // surface; DENSITY asks for the density's. Each is the engine's to the byte.
  absl::StatusOr<LoadedMapFile> file = LoadMapFile(CachedRoomMapFile());
  ASSERT_TRUE(file.ok()) << file.status();
  ASSERT_FALSE(file->state.keyframes.empty());
  const PlenoxelMap& map = *file->map;
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  MeshOptions options;
  options.min_component_triangles = 20;
  absl::StatusOr<TriangleMesh> mesh =
      ExtractObservedMesh(map, file->state.keyframes, *backend, options);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(*mesh, map.source);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_EQ(bytes, ply->bytes);

  pb::ExportRequest density_request = request;
  density_request.set_mesh_surface(pb::MESH_SURFACE_DENSITY);
  std::string density_bytes;
  const grpc::Status d = Run(density_request, &density_bytes);
  ASSERT_TRUE(d.ok()) << Describe(d);
  absl::StatusOr<TriangleMesh> density = ExtractMesh(map.grid, *backend, options);
  ASSERT_TRUE(density.ok()) << density.status();
  absl::StatusOr<PlyMesh> density_ply = EncodePlyMesh(*density, map.source);
  ASSERT_TRUE(density_ply.ok()) << density_ply.status();
  EXPECT_EQ(density_bytes, density_ply->bytes);
  EXPECT_GT(density->num_triangles(), mesh->num_triangles());  // the backs of walls

  absl::StatusOr<plx::testing::PlyMeshFile> read = plx::testing::ReadPlyMesh(bytes);
  ASSERT_TRUE(read.ok()) << read.status();
  const TriangleMesh& m = read->mesh;
  EXPECT_GT(m.num_triangles(), 1000);
  for (int32_t v : m.triangles) ASSERT_LT(v, m.num_vertices());
  for (int64_t v = 0; v < m.num_vertices(); ++v) {
    const float* n = &m.normals[3 * v];
    EXPECT_NEAR(std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), 1.0f, 1e-3f);
    // Within the 6 x 5 m room's walls, or behind them by at most the allocation band (8 cm
    // and the rest of a brick, 32 cm at 4 cm voxels): back faces that kept some colour.
    EXPECT_LE(std::abs(m.positions[3 * v]), 3.0f + 0.32f);
    EXPECT_LE(std::abs(m.positions[3 * v + 1]), 2.5f + 0.32f);
  }
}

TEST_F(ExportMeshTest, ATriangleLimitBelowTheMeshIsResourceExhausted) {
  pb::ExportRequest request = MeshRequest();
  request.set_max_triangles(10);
  std::string bytes;
  const grpc::Status s = Run(request, &bytes);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  EXPECT_NE(s.error_message().find("max_triangles"), std::string::npos) << s.error_message();
  EXPECT_TRUE(bytes.empty());
}

TEST_F(ExportMeshTest, BadOptionsNameTheirField) {
  struct Case {
    std::function<void(pb::ExportRequest*)> set;
    const char* field;
  };
  const std::vector<Case> cases = {
      {[](pb::ExportRequest* r) { r->set_format(static_cast<pb::ExportFormat>(7)); }, "format"},
      {[](pb::ExportRequest* r) { r->set_iso_level(-1.0f); }, "iso_level"},
      {[](pb::ExportRequest* r) { r->set_iso_level(std::nanf("")); }, "iso_level"},
      {[](pb::ExportRequest* r) { r->set_iso_level(INFINITY); }, "iso_level"},
      {[](pb::ExportRequest* r) { r->set_min_density(5.0f); }, "min_density"},
      {[](pb::ExportRequest* r) { r->set_max_triangles(uint64_t{1} << 40); }, "max_triangles"},
      {[](pb::ExportRequest* r) { r->set_min_component_triangles(uint64_t{1} << 40); },
       "min_component_triangles"},
      {[](pb::ExportRequest* r) { r->set_mesh_color(static_cast<pb::MeshColor>(9)); },
       "mesh_color"},
      // Mesh options on a point export.
      {[](pb::ExportRequest* r) {
         r->set_format(pb::EXPORT_FORMAT_POINTS);
         r->set_iso_level(50.0f);
       },
       "iso_level"},
      {[](pb::ExportRequest* r) {
         r->set_format(pb::EXPORT_FORMAT_POINTS);
         r->set_keep_unobserved(true);
       },
       "keep_unobserved"},
  };
  for (const Case& c : cases) {
    pb::ExportRequest request = MeshRequest();
    c.set(&request);
    std::string bytes;
    const grpc::Status s = Run(request, &bytes);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field << ": " << Describe(s);
    EXPECT_NE(s.error_message().find(c.field), std::string::npos)
        << "the message should name \"" << c.field << "\": " << s.error_message();
    EXPECT_TRUE(bytes.empty());
  }
}

}  // namespace
}  // namespace plx::server::testing

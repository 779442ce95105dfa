// Export with format MESH_GLB and a level of detail: the streamed chunks are a binary glTF file
// (header and JSON chunk parsed here; the rest by the tests' strict reader) holding the daemon's
// mesh, byte for byte what the engine writes in-process for the same map; lod_triangles gives
// at most that many triangles, and the file's extras say how many the full mesh had; the
// level-of-detail field is refused where it does not apply.
#include <gtest/gtest.h>

#include <cstring>

#include "core/cpu/cpu_backend.h"
#include "core/export/map_export.h"
#include "core/formats/glb_mesh.h"
#include "core/formats/map_file.h"
#include "tests/glb_reader.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

uint32_t Le32(const std::string& bytes, size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, bytes.data() + at, 4);
  return v;
}

class ExportGlbTest : public ::testing::Test {
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
  static pb::ExportRequest GlbRequest(uint64_t lod_triangles = 0) {
    pb::ExportRequest r;
    r.set_map("room");
    r.set_format(pb::EXPORT_FORMAT_MESH_GLB);
    r.set_lod_triangles(lod_triangles);
    return r;
  }
  static grpc::Status Run(const pb::ExportRequest& r, std::string* bytes) {
    return Export(*daemon_->stub, r, bytes);
  }
  // The same export in-process, from the map file the daemon loaded.
  static MapExport InProcess(uint64_t lod_triangles) {
    absl::StatusOr<LoadedMapFile> map = LoadMapFile(CachedRoomMapFile());
    EXPECT_TRUE(map.ok()) << map.status();
    if (!map.ok()) return {};
    std::unique_ptr<Backend> backend = MakeCpuBackend(2);
    ExportSpec spec;
    spec.mesh = true;
    spec.mesh_format = MeshFileFormat::kGlb;
    spec.lod_triangles = static_cast<int64_t>(lod_triangles);
    absl::StatusOr<MapExport> file =
        ExportMap(spec, *map->map, map->state.keyframes, *backend);
    EXPECT_TRUE(file.ok()) << file.status();
    return file.ok() ? *file : MapExport{};
  }
  static TestDaemon* daemon_;
};
TestDaemon* ExportGlbTest::daemon_ = nullptr;

TEST_F(ExportGlbTest, TheChunksAreTheEnginesGlbOfTheMap) {
  std::string bytes;
  const grpc::Status s = Run(GlbRequest(), &bytes);
  ASSERT_TRUE(s.ok()) << Describe(s);

  // The GLB header: magic "glTF", version 2, the total length; then the JSON chunk.
  ASSERT_GE(bytes.size(), 20u);
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(Le32(bytes, 4), 2u);
  EXPECT_EQ(Le32(bytes, 8), bytes.size());
  const uint32_t json_bytes = Le32(bytes, 12);
  EXPECT_EQ(bytes.substr(16, 4), "JSON");
  EXPECT_EQ(json_bytes % 4, 0u);
  ASSERT_LE(20u + json_bytes, bytes.size());
  const nlohmann::json json =
      nlohmann::json::parse(bytes.substr(20, json_bytes), nullptr, /*allow_exceptions=*/false);
  ASSERT_FALSE(json.is_discarded());
  const nlohmann::json& primitive = json["meshes"][0]["primitives"][0];
  const size_t vertices = json["accessors"][primitive["attributes"]["POSITION"].get<int>()]
                              ["count"].get<size_t>();
  const size_t indices = json["accessors"][primitive["indices"].get<int>()]["count"].get<size_t>();
  EXPECT_GT(indices / 3, 1000u);

  const absl::StatusOr<plx::testing::GlbFile> file = plx::testing::ReadGlb(bytes);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(static_cast<size_t>(file->mesh.num_vertices()), vertices);
  EXPECT_EQ(static_cast<size_t>(file->mesh.num_triangles()), indices / 3);
  EXPECT_EQ(json["asset"]["extras"]["plenoxd"]["full_triangles"], indices / 3);

  EXPECT_EQ(bytes, InProcess(0).bytes);
}

TEST_F(ExportGlbTest, ATriangleBudgetGivesAtMostThatMany) {
  std::string full;
  ASSERT_TRUE(Run(GlbRequest(), &full).ok());
  const absl::StatusOr<GlbMeshInfo> full_info = ReadGlbMeshInfo(full);
  ASSERT_TRUE(full_info.ok()) << full_info.status();
  for (const uint64_t budget : {static_cast<uint64_t>(full_info->triangles / 10), uint64_t{500}}) {
    SCOPED_TRACE(budget);
    std::string bytes;
    const grpc::Status s = Run(GlbRequest(budget), &bytes);
    ASSERT_TRUE(s.ok()) << Describe(s);
    const absl::StatusOr<plx::testing::GlbFile> file = plx::testing::ReadGlb(bytes);
    ASSERT_TRUE(file.ok()) << file.status();
    EXPECT_LE(static_cast<uint64_t>(file->mesh.num_triangles()), budget);
    EXPECT_GT(static_cast<uint64_t>(file->mesh.num_triangles()), budget / 2);
    const nlohmann::json& extras = file->json["asset"]["extras"]["plenoxd"];
    EXPECT_EQ(extras["full_triangles"], full_info->triangles);
    EXPECT_GT(extras["lod_error_m"].get<double>(), 0.0);
    EXPECT_LT(bytes.size(), full.size());
    EXPECT_EQ(bytes, InProcess(budget).bytes);
  }
  // The same budget on a PLY mesh.
  pb::ExportRequest ply = GlbRequest(500);
  ply.set_format(pb::EXPORT_FORMAT_MESH);
  std::string bytes;
  ASSERT_TRUE(Run(ply, &bytes).ok());
  EXPECT_EQ(bytes.rfind("ply\n", 0), 0u);
  EXPECT_NE(bytes.find("\nelement face "), std::string::npos);
  const size_t at = bytes.find("\nelement face ") + 14;
  EXPECT_LE(std::stoll(bytes.substr(at, bytes.find('\n', at) - at)), 500);
}

TEST_F(ExportGlbTest, TheBudgetIsRefusedWhereItDoesNotApply) {
  pb::ExportRequest points;
  points.set_map("room");
  points.set_lod_triangles(100);
  pb::ExportRequest too_many = GlbRequest(uint64_t{1} << 40);
  pb::ExportRequest unknown = GlbRequest();
  unknown.set_format(static_cast<pb::ExportFormat>(3));
  for (const pb::ExportRequest& request : {points, too_many, unknown}) {
    std::string bytes;
    const grpc::Status s = Run(request, &bytes);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(s);
    EXPECT_NE(s.error_message().find(request.format() == 3 ? "format" : "lod_triangles"),
              std::string::npos)
        << s.error_message();
    EXPECT_TRUE(bytes.empty());
  }
}

}  // namespace
}  // namespace plx::server::testing

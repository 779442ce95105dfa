// The binary glTF writer (core/formats/glb_mesh.h), read back by the tests' own strict reader
// (tests/glb_reader.h: header, chunk lengths and 4-byte alignment, accessors through their
// views, indices in range) and by tinygltf's loader: the mesh survives exactly, POSITION has the
// exact min/max, 16-bit indices up to 65 535 vertices and 32-bit past them, unit normals, the
// node's +Z-up-to-+Y-up turn, the unlit double-sided material, the asset's plenoxd extras, an
// empty mesh, ReadGlbMeshInfo from the file's beginning only, and the refusals.
#include "core/formats/glb_mesh.h"

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "tests/glb_reader.h"

namespace plx {
namespace {

using testing::GlbFile;
using testing::ReadGlb;

// A strip of `quads` quads along x (2 triangles each), with normals of length 2 along +Z and
// colours that differ per vertex.
TriangleMesh Strip(int quads) {
  TriangleMesh mesh;
  for (int i = 0; i <= quads; ++i) {
    for (int j = 0; j < 2; ++j) {
      mesh.positions.insert(mesh.positions.end(), {0.01f * i - 1.5f, 0.25f * j + 0.125f,
                                                   0.001f * static_cast<float>(i % 7)});
      mesh.normals.insert(mesh.normals.end(), {0.0f, 0.0f, 2.0f});
      mesh.colors.insert(mesh.colors.end(), {static_cast<uint8_t>(i % 251),
                                             static_cast<uint8_t>(j * 200),
                                             static_cast<uint8_t>((i * 7) % 256)});
    }
  }
  for (int i = 0; i < quads; ++i) {
    const int32_t a = 2 * i, b = 2 * i + 1, c = 2 * i + 2, d = 2 * i + 3;
    mesh.triangles.insert(mesh.triangles.end(), {a, c, d, a, d, b});
  }
  return mesh;
}

GlbFile EncodeAndRead(const TriangleMesh& mesh, const GlbMeshMetadata& metadata = {}) {
  const absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(mesh, metadata);
  EXPECT_TRUE(glb.ok()) << glb.status();
  if (!glb.ok()) return {};
  EXPECT_EQ(glb->bytes.size() % 4, 0u);
  absl::StatusOr<GlbFile> file = ReadGlb(glb->bytes);
  EXPECT_TRUE(file.ok()) << file.status();
  return file.ok() ? *file : GlbFile{};
}

TEST(GlbMeshTest, TheMeshSurvivesExactlyWithMinMaxAndUnitNormals) {
  const TriangleMesh mesh = Strip(40);
  GlbMeshMetadata metadata;
  metadata.source = "tests: a strip";
  metadata.full_triangles = 800;
  metadata.lod_error_m = 0.0042;
  const absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(mesh, metadata);
  ASSERT_TRUE(glb.ok()) << glb.status();
  EXPECT_EQ(glb->vertices, mesh.num_vertices());
  EXPECT_EQ(glb->faces, mesh.num_triangles());
  const absl::StatusOr<GlbFile> file = ReadGlb(glb->bytes);
  ASSERT_TRUE(file.ok()) << file.status();

  EXPECT_EQ(file->mesh.positions, mesh.positions);
  EXPECT_EQ(file->mesh.colors, mesh.colors);
  EXPECT_EQ(file->mesh.triangles, mesh.triangles);
  EXPECT_EQ(file->index_component_type, 5123);  // unsigned short: 82 vertices
  for (size_t i = 0; i < mesh.normals.size(); ++i) {
    EXPECT_EQ(file->mesh.normals[i], mesh.normals[i] / 2.0f) << i;  // renormalised
  }
  // min/max are the positions' own extremes, to the bit (a loader may check them).
  for (int c = 0; c < 3; ++c) {
    float lo = mesh.positions[c], hi = mesh.positions[c];
    for (size_t v = 0; v < mesh.positions.size(); v += 3) {
      lo = std::min(lo, mesh.positions[v + c]);
      hi = std::max(hi, mesh.positions[v + c]);
    }
    EXPECT_EQ(file->position_min[c], static_cast<double>(lo)) << c;
    EXPECT_EQ(file->position_max[c], static_cast<double>(hi)) << c;
  }

  const nlohmann::json& j = file->json;
  EXPECT_EQ(j["asset"]["version"], "2.0");
  EXPECT_EQ(j["scene"], 0);
  ASSERT_EQ(j["scenes"].size(), 1u);
  EXPECT_EQ(j["scenes"][0]["nodes"], nlohmann::json::array({0}));
  ASSERT_EQ(j["nodes"].size(), 1u);
  EXPECT_EQ(j["nodes"][0]["mesh"], 0);
  // -90 degrees about X: map +Z up is glTF +Y up, map +Y forward is glTF -Z.
  const std::vector<double> q = j["nodes"][0]["rotation"].get<std::vector<double>>();
  ASSERT_EQ(q.size(), 4u);
  EXPECT_NEAR(q[0], -std::sqrt(0.5), 1e-12);
  EXPECT_EQ(q[1], 0.0);
  EXPECT_EQ(q[2], 0.0);
  EXPECT_NEAR(q[3], std::sqrt(0.5), 1e-12);
  const nlohmann::json& material = j["materials"][0];
  EXPECT_EQ(material["doubleSided"], true);
  EXPECT_TRUE(material["extensions"].contains("KHR_materials_unlit"));
  EXPECT_EQ(material["pbrMetallicRoughness"]["metallicFactor"], 0.0);
  // [0, 0, 0] is the default and left out (an empty array, which tinygltf writes for a field
  // left empty, would be invalid glTF).
  EXPECT_FALSE(material.contains("emissiveFactor"));
  EXPECT_EQ(j["extensionsUsed"], nlohmann::json::array({"KHR_materials_unlit"}));
  EXPECT_FALSE(j.contains("extensionsRequired"));  // loaders without it fall back to PBR
  EXPECT_EQ(j["meshes"][0]["primitives"][0]["material"], 0);
  const nlohmann::json& extras = j["asset"]["extras"]["plenoxd"];
  EXPECT_EQ(extras["source"], "tests: a strip");
  EXPECT_EQ(extras["triangles"], 80);
  EXPECT_EQ(extras["full_triangles"], 800);
  EXPECT_EQ(extras["lod_error_m"], 0.0042);
  EXPECT_EQ(extras["up"], "+Z");
}

TEST(GlbMeshTest, TinygltfsLoaderReadsItWithoutComplaint) {
  const TriangleMesh mesh = Strip(33);
  const absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(mesh, {});
  ASSERT_TRUE(glb.ok()) << glb.status();
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromMemory(&model, &err, &warn,
                                          reinterpret_cast<const unsigned char*>(glb->bytes.data()),
                                          static_cast<unsigned int>(glb->bytes.size())))
      << err;
  EXPECT_TRUE(err.empty()) << err;
  EXPECT_TRUE(warn.empty()) << warn;
  ASSERT_EQ(model.meshes.size(), 1u);
  const tinygltf::Primitive& p = model.meshes[0].primitives[0];
  EXPECT_EQ(model.accessors[p.attributes.at("POSITION")].count, 68u);
  EXPECT_EQ(model.accessors[p.attributes.at("NORMAL")].count, 68u);
  EXPECT_EQ(model.accessors[p.attributes.at("COLOR_0")].count, 68u);
  EXPECT_EQ(model.accessors[p.indices].count, 3u * 66);
  EXPECT_EQ(p.mode, TINYGLTF_MODE_TRIANGLES);
}

TEST(GlbMeshTest, IndicesAre16BitUpTo65535VerticesAnd32BitPast) {
  // 2 * (quads + 1) vertices: 65534 at 32766 quads, 65536 at 32767.
  const GlbFile small = EncodeAndRead(Strip(32766));
  EXPECT_EQ(small.mesh.num_vertices(), 65534);
  EXPECT_EQ(small.index_component_type, 5123);
  TriangleMesh odd = Strip(32766);  // one more vertex, used: 65535, the most for 16 bits
  for (int c = 0; c < 3; ++c) {
    odd.positions.push_back(odd.positions[c] + 0.5f);
    odd.normals.push_back(odd.normals[c]);
    odd.colors.push_back(9);
  }
  odd.triangles.insert(odd.triangles.end(), {0, 1, 65534});
  const GlbFile edge = EncodeAndRead(odd);
  EXPECT_EQ(edge.mesh.num_vertices(), 65535);
  EXPECT_EQ(edge.index_component_type, 5123);
  EXPECT_EQ(edge.mesh.triangles, odd.triangles);
  const TriangleMesh large_mesh = Strip(32767);
  const GlbFile large = EncodeAndRead(large_mesh);
  EXPECT_EQ(large.mesh.num_vertices(), 65536);
  EXPECT_EQ(large.index_component_type, 5125);
  EXPECT_EQ(large.mesh.triangles, large_mesh.triangles);
  EXPECT_EQ(large.mesh.positions, large_mesh.positions);
}

TEST(GlbMeshTest, ZeroAndNonFiniteNormalsBecomeUp) {
  TriangleMesh mesh = Strip(1);
  mesh.normals[0] = mesh.normals[1] = mesh.normals[2] = 0.0f;
  mesh.normals[3] = std::nanf("");
  mesh.normals[6] = 3.0f;  // (3, 0, 2): normalised
  mesh.normals[8] = 4.0f;
  const GlbFile file = EncodeAndRead(mesh);
  const std::vector<float>& n = file.mesh.normals;
  ASSERT_EQ(n.size(), 12u);
  EXPECT_EQ((std::vector<float>{n[0], n[1], n[2]}), (std::vector<float>{0, 0, 1}));
  EXPECT_EQ((std::vector<float>{n[3], n[4], n[5]}), (std::vector<float>{0, 0, 1}));
  EXPECT_FLOAT_EQ(n[6], 0.6f);
  EXPECT_FLOAT_EQ(n[8], 0.8f);
}

TEST(GlbMeshTest, AnEmptyMeshIsAValidSceneWithoutAMesh) {
  const absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(TriangleMesh(), {});
  ASSERT_TRUE(glb.ok()) << glb.status();
  EXPECT_EQ(glb->vertices, 0);
  EXPECT_EQ(glb->faces, 0);
  const absl::StatusOr<GlbFile> file = ReadGlb(glb->bytes);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->bin_chunk_bytes, 0u);
  EXPECT_FALSE(file->json.contains("meshes"));
  EXPECT_FALSE(file->json.contains("accessors"));  // glTF forbids count 0
  EXPECT_EQ(file->json["nodes"].size(), 1u);
  EXPECT_FALSE(file->json["nodes"][0].contains("mesh"));
  const absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(glb->bytes);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->vertices, 0);
  EXPECT_EQ(info->triangles, 0);
}

TEST(GlbMeshTest, SourceTextThatIsNotUtf8IsWrittenWithQuestionMarks) {
  GlbMeshMetadata metadata;
  metadata.source = std::string("caf\xc3\xa9 \xff\xfe room \xe2\x82", 16);
  const GlbFile file = EncodeAndRead(Strip(2), metadata);
  EXPECT_EQ(file.json["asset"]["extras"]["plenoxd"]["source"], "caf\xc3\xa9 ?? room ??");
}

TEST(GlbMeshTest, TheSameMeshGivesTheSameBytes) {
  const absl::StatusOr<GlbMesh> a = EncodeGlbMesh(Strip(50), {"s", 0, 0.0});
  const absl::StatusOr<GlbMesh> b = EncodeGlbMesh(Strip(50), {"s", 0, 0.0});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->bytes, b->bytes);
}

TEST(GlbMeshTest, InfoComesFromTheHeaderAndJsonChunkAlone) {
  GlbMeshMetadata metadata;
  metadata.full_triangles = 12345;
  metadata.lod_error_m = 0.01;
  const absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(Strip(100), metadata);
  ASSERT_TRUE(glb.ok()) << glb.status();
  const absl::StatusOr<int64_t> needed = GlbInfoBytes(glb->bytes.substr(0, 20));
  ASSERT_TRUE(needed.ok()) << needed.status();
  EXPECT_LT(*needed, 4096);  // the JSON is small, the buffer follows it
  const absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(glb->bytes.substr(0, *needed));
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->file_bytes, static_cast<int64_t>(glb->bytes.size()));
  EXPECT_EQ(info->vertices, 202);
  EXPECT_EQ(info->triangles, 200);
  EXPECT_EQ(info->full_triangles, 12345);
  EXPECT_DOUBLE_EQ(info->lod_error_m, 0.01);

  EXPECT_EQ(ReadGlbMeshInfo(glb->bytes.substr(0, *needed - 1)).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadGlbMeshInfo("ply\nformat binary_little_endian 1.0\n").status().code(),
            absl::StatusCode::kInvalidArgument);
  std::string not_json = glb->bytes.substr(0, *needed);
  not_json[20] = '[';
  not_json[21] = '[';
  EXPECT_EQ(ReadGlbMeshInfo(not_json).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(GlbMeshTest, InconsistentOrNonFiniteMeshesAreRefused) {
  TriangleMesh mesh = Strip(3);
  mesh.colors.pop_back();
  EXPECT_EQ(EncodeGlbMesh(mesh, {}).status().code(), absl::StatusCode::kInvalidArgument);
  mesh = Strip(3);
  mesh.triangles[4] = 99;
  EXPECT_EQ(EncodeGlbMesh(mesh, {}).status().code(), absl::StatusCode::kInvalidArgument);
  mesh = Strip(3);
  mesh.positions[5] = std::numeric_limits<float>::infinity();
  const absl::StatusOr<GlbMesh> r = EncodeGlbMesh(mesh, {});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("vertex 1"), std::string::npos) << r.status();
}

}  // namespace
}  // namespace plx

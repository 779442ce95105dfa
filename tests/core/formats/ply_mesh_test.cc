// The PLY mesh writer: the header MeshLab/Open3D/Blender expect and a byte-exact round trip
// through the tests' reader.
#include "core/formats/ply_mesh.h"

#include <gtest/gtest.h>

#include "gmock/gmock.h"
#include "tests/ply_mesh_reader.h"

namespace plx {
namespace {

TriangleMesh Tetrahedron() {
  TriangleMesh m;
  m.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1.5f};
  m.normals = {-0.57735f, -0.57735f, -0.57735f, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.colors = {0, 1, 2, 255, 128, 7, 10, 20, 30, 40, 50, 60};
  m.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  return m;
}

TEST(PlyMeshTest, RoundTripsThroughTheReader) {
  const TriangleMesh mesh = Tetrahedron();
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(mesh, "room\nscan");
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_EQ(ply->vertices, 4);
  EXPECT_EQ(ply->faces, 4);
  EXPECT_THAT(ply->bytes, ::testing::StartsWith(
                              "ply\nformat binary_little_endian 1.0\n"
                              "comment plenoxd map: room scan\nelement vertex 4\n"
                              "property float x\nproperty float y\nproperty float z\n"
                              "property float nx\nproperty float ny\nproperty float nz\n"
                              "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                              "element face 4\nproperty list uchar int vertex_indices\n"
                              "end_header\n"));
  absl::StatusOr<testing::PlyMeshFile> read = testing::ReadPlyMesh(ply->bytes);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->comment, "plenoxd map: room scan");
  EXPECT_EQ(read->mesh.positions, mesh.positions);
  EXPECT_EQ(read->mesh.normals, mesh.normals);
  EXPECT_EQ(read->mesh.colors, mesh.colors);
  EXPECT_EQ(read->mesh.triangles, mesh.triangles);
  // 4 vertices of 27 bytes and 4 faces of 13 after the header.
  EXPECT_EQ(ply->bytes.size() - ply->bytes.find("end_header\n") - 11, 4u * 27 + 4u * 13);
}

TEST(PlyMeshTest, AnEmptyMeshIsAValidFile) {
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(TriangleMesh{}, "");
  ASSERT_TRUE(ply.ok()) << ply.status();
  absl::StatusOr<testing::PlyMeshFile> read = testing::ReadPlyMesh(ply->bytes);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->mesh.num_vertices(), 0);
  EXPECT_EQ(read->comment, "plenoxd map: unnamed");
}

TEST(PlyMeshTest, RejectsInconsistentMeshes) {
  TriangleMesh bad = Tetrahedron();
  bad.triangles.push_back(4);
  bad.triangles.push_back(0);
  bad.triangles.push_back(1);
  EXPECT_EQ(EncodePlyMesh(bad, "").status().code(), absl::StatusCode::kInvalidArgument);
  bad = Tetrahedron();
  bad.colors.pop_back();
  EXPECT_EQ(EncodePlyMesh(bad, "").status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plx

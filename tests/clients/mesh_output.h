// What `plenox export --mesh` runs (in-process or remote) are checked for: the file is a mesh
// the tests' PLY or glTF reader reads, and the --json line's counts are the file's.
#pragma once

#include <string>

#include <gtest/gtest.h>

#include "tests/clients/cli_runner.h"
#include "tests/glb_reader.h"
#include "tests/ply_mesh_reader.h"

namespace plx::testing {

// The mesh at `path` (a failure and an empty mesh when it does not read).
inline TriangleMesh ExpectMeshFileMatchingJson(const std::string& path, const CommandResult& r) {
  const absl::StatusOr<PlyMeshFile> file = ReadPlyMesh(ReadFileToString(path));
  EXPECT_TRUE(file.ok()) << file.status();
  if (!file.ok()) return {};
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(JsonNumber(json, "vertices").value_or(-1), file->mesh.num_vertices()) << r.Describe();
  EXPECT_EQ(JsonNumber(json, "faces").value_or(-1), file->mesh.num_triangles()) << r.Describe();
  return file->mesh;
}

// The same for a binary glTF file (--format glb); also checks the JSON's format and the file's
// record of the full mesh's triangles.
inline GlbFile ExpectGlbFileMatchingJson(const std::string& path, const CommandResult& r) {
  const absl::StatusOr<GlbFile> file = ReadGlb(ReadFileToString(path));
  EXPECT_TRUE(file.ok()) << file.status();
  if (!file.ok()) return {};
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(json.count("format") ? json.at("format").text : "", "glb") << r.Describe();
  EXPECT_EQ(JsonNumber(json, "vertices").value_or(-1), file->mesh.num_vertices()) << r.Describe();
  EXPECT_EQ(JsonNumber(json, "faces").value_or(-1), file->mesh.num_triangles()) << r.Describe();
  EXPECT_EQ(JsonNumber(json, "full_faces").value_or(-1),
            file->json["asset"]["extras"]["plenoxd"]["full_triangles"].get<double>())
      << r.Describe();
  return *file;
}

}  // namespace plx::testing

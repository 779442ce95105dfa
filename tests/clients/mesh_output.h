// What `plenox export --mesh` runs (in-process or remote) are checked for: the file is a mesh
// the tests' PLY reader reads, and the --json line's counts are the file's.
#pragma once

#include <string>

#include <gtest/gtest.h>

#include "tests/clients/cli_runner.h"
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

}  // namespace plx::testing

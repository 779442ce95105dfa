// An indexed triangle mesh with per-vertex normals and colours: what mesh extraction
// (core/mesh) produces, simplification (core/mesh/mesh_simplify.h) reduces and the PLY and glTF
// writers (core/formats/ply_mesh.h, glb_mesh.h) write. Plain arrays so a writer or a test reads
// them without knowing how the mesh was made.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/status.h"

namespace plx {

struct TriangleMesh {
  std::vector<float> positions;  // [vertices * 3] world x y z, metres
  std::vector<float> normals;    // [vertices * 3] unit, pointing into free space
  std::vector<uint8_t> colors;   // [vertices * 3] RGB
  // [triangles * 3] vertex indices, counter-clockwise seen from the side the normals face.
  std::vector<int32_t> triangles;

  int64_t num_vertices() const { return static_cast<int64_t>(positions.size() / 3); }
  int64_t num_triangles() const { return static_cast<int64_t>(triangles.size() / 3); }
};

// InvalidArgument when the arrays disagree in size (positions, normals and colours three
// values a vertex, three indices a triangle) or a triangle names a vertex that does not exist:
// what every writer and the simplifier check before they index the arrays.
absl::Status CheckTriangleMesh(const TriangleMesh& mesh);

}  // namespace plx

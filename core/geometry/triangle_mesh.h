// An indexed triangle mesh with per-vertex normals and colours: what mesh extraction
// (core/mesh) produces and the PLY mesh writer (core/formats/ply_mesh.h) writes. Plain arrays
// so a writer or a test reads them without knowing how the mesh was made.
#pragma once

#include <cstdint>
#include <vector>

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

}  // namespace plx

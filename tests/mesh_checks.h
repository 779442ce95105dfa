// Topology checks of triangle meshes for the mesh tests.
#pragma once

#include <cstdint>
#include <map>
#include <utility>

#include "core/geometry/triangle_mesh.h"

namespace plx::testing {

struct EdgeUse {
  int64_t edges = 0;             // distinct undirected edges
  int64_t not_twice = 0;         // undirected edges not shared by exactly two triangles
  int64_t same_direction = 0;    // directed edges used more than once (orientation flips)
};

// A closed, consistently oriented surface has not_twice == 0 and same_direction == 0.
inline EdgeUse CountEdgeUse(const TriangleMesh& mesh) {
  std::map<std::pair<int32_t, int32_t>, int> directed;
  for (int64_t t = 0; t < mesh.num_triangles(); ++t) {
    for (int c = 0; c < 3; ++c) {
      ++directed[{mesh.triangles[3 * t + c], mesh.triangles[3 * t + (c + 1) % 3]}];
    }
  }
  EdgeUse use;
  for (const auto& [edge, n] : directed) {
    if (n > 1) ++use.same_direction;
    const auto reverse = directed.find({edge.second, edge.first});
    const int total = n + (reverse == directed.end() ? 0 : reverse->second);
    if (edge.first < edge.second || reverse == directed.end()) {
      ++use.edges;
      if (total != 2) ++use.not_twice;
    }
  }
  return use;
}

}  // namespace plx::testing

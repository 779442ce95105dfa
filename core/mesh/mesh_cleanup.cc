#include "core/mesh/mesh_cleanup.h"

#include <cstddef>
#include <numeric>
#include <utility>

namespace plx {
namespace {

// Union-find with path halving; roots are the smaller index, so results do not depend on
// the order of unions.
int32_t Find(std::vector<int32_t>& parent, int32_t v) {
  while (parent[v] != v) {
    parent[v] = parent[parent[v]];
    v = parent[v];
  }
  return v;
}

void Union(std::vector<int32_t>& parent, int32_t a, int32_t b) {
  a = Find(parent, a);
  b = Find(parent, b);
  if (a == b) return;
  if (a < b) {
    parent[b] = a;
  } else {
    parent[a] = b;
  }
}

}  // namespace

int64_t KeepTriangles(TriangleMesh* mesh, const std::vector<uint8_t>& keep) {
  const int64_t triangles = mesh->num_triangles();
  const int64_t vertices = mesh->num_vertices();
  const std::vector<int32_t>& t = mesh->triangles;
  std::vector<int32_t> kept;
  kept.reserve(t.size());
  for (int64_t i = 0; i < triangles; ++i) {
    if (!keep[i]) continue;
    for (int c = 0; c < 3; ++c) kept.push_back(t[3 * i + c]);
  }
  if (static_cast<int64_t>(kept.size()) == 3 * triangles) return 0;
  // Renumber the vertices the kept triangles use, moving each down to its new place.
  std::vector<int32_t> remap(static_cast<size_t>(vertices), -1);
  for (int32_t v : kept) remap[v] = 0;
  int32_t next = 0;
  for (int64_t v = 0; v < vertices; ++v) {
    if (remap[v] < 0) continue;
    remap[v] = next;
    for (int c = 0; c < 3; ++c) {
      mesh->positions[3 * next + c] = mesh->positions[3 * v + c];
      mesh->normals[3 * next + c] = mesh->normals[3 * v + c];
      mesh->colors[3 * next + c] = mesh->colors[3 * v + c];
    }
    ++next;
  }
  mesh->positions.resize(3 * static_cast<size_t>(next));
  mesh->normals.resize(3 * static_cast<size_t>(next));
  mesh->colors.resize(3 * static_cast<size_t>(next));
  for (int32_t& v : kept) v = remap[v];
  const int64_t removed = triangles - static_cast<int64_t>(kept.size() / 3);
  mesh->triangles = std::move(kept);
  return removed;
}

int64_t RemoveSmallComponents(TriangleMesh* mesh, int64_t min_triangles) {
  const int64_t triangles = mesh->num_triangles();
  if (min_triangles <= 1 || triangles == 0) return 0;
  const int64_t vertices = mesh->num_vertices();
  std::vector<int32_t> parent(static_cast<size_t>(vertices));
  std::iota(parent.begin(), parent.end(), 0);
  const std::vector<int32_t>& t = mesh->triangles;
  for (int64_t i = 0; i < triangles; ++i) {
    Union(parent, t[3 * i], t[3 * i + 1]);
    Union(parent, t[3 * i], t[3 * i + 2]);
  }
  std::vector<int64_t> size(static_cast<size_t>(vertices), 0);
  for (int64_t i = 0; i < triangles; ++i) ++size[Find(parent, t[3 * i])];
  std::vector<uint8_t> keep(static_cast<size_t>(triangles));
  for (int64_t i = 0; i < triangles; ++i) keep[i] = size[Find(parent, t[3 * i])] >= min_triangles;
  return KeepTriangles(mesh, keep);
}

}  // namespace plx

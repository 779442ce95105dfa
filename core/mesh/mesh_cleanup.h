// Removing triangles from a mesh after extraction: the ones no view saw and the small floating
// components (triangles joined through shared vertices) that a few wrong depth pixels leave in
// free space.
#pragma once

#include <cstdint>
#include <vector>

#include "core/geometry/triangle_mesh.h"

namespace plx {

// Keeps the triangles whose flag in `keep` [num_triangles] is non-zero, and the vertices they
// use; kept vertices and triangles stay in their order. Returns how many triangles went.
int64_t KeepTriangles(TriangleMesh* mesh, const std::vector<uint8_t>& keep);

// Removes every component with fewer than `min_triangles` triangles (KeepTriangles).
int64_t RemoveSmallComponents(TriangleMesh* mesh, int64_t min_triangles);

}  // namespace plx

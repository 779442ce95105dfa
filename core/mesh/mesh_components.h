// Connected components of a triangle mesh (triangles joined through shared vertices), for
// dropping the small floating pieces mesh extraction leaves in free space.
#pragma once

#include <cstdint>

#include "core/geometry/triangle_mesh.h"

namespace plx {

// Removes every component with fewer than `min_triangles` triangles, and the vertices only
// they used; the kept vertices and triangles stay in their order. Returns how many triangles
// were removed.
int64_t RemoveSmallComponents(TriangleMesh* mesh, int64_t min_triangles);

}  // namespace plx

// The marching-cubes case table, derived at run time from the cube's topology instead of being
// written out (core/kernels/marching_cubes_table.cc explains the construction).
//
// Cube conventions (used by core/kernels/marching_cubes.h too): corner k sits at offset
// (k & 1, (k >> 1) & 1, (k >> 2) & 1). Edge e runs along axis a = e / 4; its two other
// coordinates are bit 0 (on axis (a + 1) % 3) and bit 1 (on axis (a + 2) % 3) of e % 4. A case
// is the 8-bit mask of the corners that are inside (density above the iso-level).
#pragma once

#include <cstdint>

#include "core/common/host_device.h"

namespace plx {

// The most triangles one case produces with this construction (checked when the table is
// built; the cases with the most are 5, as in the classic table).
inline constexpr int kMaxCubeTriangles = 5;

struct MarchingCubesTable {
  uint8_t triangle_count[256];
  // Edge ids, three per triangle, counter-clockwise seen from outside (the low-density side).
  int8_t edges[256][3 * kMaxCubeTriangles];
};

// Corner offsets of cube edge e: the low end (bit a clear) and the axis it runs along.
PLX_HD int CubeEdgeAxis(int e) { return e >> 2; }
PLX_HD int CubeEdgeLowCorner(int e) {
  const int axis = e >> 2;
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  return ((e & 1) << a1) | (((e >> 1) & 1) << a2);
}

// Fills `table`. Always the same result; cheap (256 cases), so callers build one where they
// need it (e.g. in memory the backend can read).
void BuildMarchingCubesTable(MarchingCubesTable* table);

}  // namespace plx

// Building the marching-cubes table from the cube's topology.
//
// The surface of a case meets each cube face in segments joining the face's crossed edges. On
// each face (walked counter-clockwise seen from outside the cube), an edge whose walk goes from
// an inside to an outside corner "leaves" the inside region and one going the other way
// "enters" it; each run of inside corners lies between an enter and the next leave, and a
// segment joins the two. On a face with all four edges crossed (two diagonal inside corners,
// the ambiguous face) this keeps the two inside corners apart. The choice depends only on the
// face's own four corners, so the two cubes sharing a face always draw the same segments there,
// which makes the mesh watertight across cells.
//
// Every crossed edge lies on two faces and is walked in opposite directions on them, so it is a
// "leave" on one and an "enter" on the other: directing each segment from its leave edge to its
// enter edge makes every crossed edge have one segment in and one out, and the segments form
// closed loops. Each loop is one polygon of the surface inside the cube, fanned into triangles.
// Walking the loop this way goes clockwise seen from outside the surface, so the fan takes the
// vertices in reverse order.
#include "core/kernels/marching_cubes_table.h"

#include <cstring>

namespace plx {
namespace {

// The edge joining corners c0 and c1 (which differ in exactly one bit).
int EdgeBetween(int c0, int c1) {
  const int low = c0 & c1;
  const int axis = (c0 ^ c1) == 1 ? 0 : ((c0 ^ c1) == 2 ? 1 : 2);
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  return axis * 4 + ((low >> a1) & 1) + 2 * ((low >> a2) & 1);
}

// The four corners of face (axis, side) in counter-clockwise order seen from outside the cube.
// With (axis, a1, a2) right-handed, (0,0) (1,0) (1,1) (0,1) in (a1, a2) turns counter-clockwise
// about +axis, i.e. seen from the side = 1 face's outside; the side = 0 face takes it reversed.
void FaceCorners(int axis, int side, int corners[4]) {
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  const int base = side << axis;
  const int ccw[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int i = 0; i < 4; ++i) {
    const int j = side == 1 ? i : (4 - i) % 4;
    corners[i] = base | (ccw[j][0] << a1) | (ccw[j][1] << a2);
  }
}

void BuildCase(int inside_mask, int8_t edges_out[3 * kMaxCubeTriangles], uint8_t* count_out) {
  auto inside = [inside_mask](int corner) { return ((inside_mask >> corner) & 1) != 0; };
  int next[12];
  for (int& n : next) n = -1;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      int corners[4];
      FaceCorners(axis, side, corners);
      // For each leave at walk position i, the enter that precedes it: the last enter seen
      // walking backwards from i (the corners between them are the inside run).
      for (int i = 0; i < 4; ++i) {
        const int a = corners[i], b = corners[(i + 1) % 4];
        if (!(inside(a) && !inside(b))) continue;
        for (int back = 1; back <= 3; ++back) {
          const int j = (i + 4 - back) % 4;
          const int c = corners[j], d = corners[(j + 1) % 4];
          if (!inside(c) && inside(d)) {
            next[EdgeBetween(a, b)] = EdgeBetween(c, d);
            break;
          }
        }
      }
    }
  }
  bool used[12] = {};
  int triangles = 0;
  for (int start = 0; start < 12; ++start) {
    if (next[start] < 0 || used[start]) continue;
    int loop[12];
    int n = 0;
    for (int e = start; !used[e]; e = next[e]) {
      used[e] = true;
      loop[n++] = e;
    }
    for (int i = 1; i + 1 < n; ++i) {
      // Never full (5 is the most any case makes, see kMaxCubeTriangles and its test); the
      // check only keeps a wrong constant from writing past the row.
      if (triangles >= kMaxCubeTriangles) break;
      edges_out[3 * triangles + 0] = static_cast<int8_t>(loop[0]);
      edges_out[3 * triangles + 1] = static_cast<int8_t>(loop[i + 1]);
      edges_out[3 * triangles + 2] = static_cast<int8_t>(loop[i]);
      ++triangles;
    }
  }
  *count_out = static_cast<uint8_t>(triangles);
}

}  // namespace

void BuildMarchingCubesTable(MarchingCubesTable* table) {
  std::memset(table, 0, sizeof(*table));
  for (int c = 0; c < 256; ++c) {
    for (int8_t& e : table->edges[c]) e = -1;
    BuildCase(c, table->edges[c], &table->triangle_count[c]);
  }
}

}  // namespace plx

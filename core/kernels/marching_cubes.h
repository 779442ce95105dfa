// Marching cubes on the density field of the brick grid, per cell and per mesh vertex (the
// drivers are in core/kernels/marching_cubes_impl.h, the host side in core/mesh/).
//
// Work items are stored vertices (slot * 512 + local), each the lowest corner of one cell. A
// cell is meshed only when all 8 of its corners are stored: unstored space is space the map
// knows nothing about (allocation covers a band around every measured surface, in front of and
// behind it), so a crossing from a stored solid vertex into it would be a wall the map never
// saw. The real surfaces lie inside the band, between stored vertices.
//
// A mesh vertex is identified by the cell edge it lies on: the edge key packs the edge's low
// vertex and its axis. Cells sharing an edge compute the same key, which is how the host merges
// duplicate vertices; the vertex's position, normal and colour are then computed once per key.
#pragma once

#include <cstdint>

#include "core/common/host_device.h"
#include "core/grid/grid_view.h"
#include "core/kernels/marching_cubes_table.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/vec3.h"

namespace plx {

// Marching cubes reads a field in the grid's layout through a GridView's density tables: the
// density itself, or the observed surface's signed field (core/mesh/observed_surface.h). A
// vertex holding this value has none (no view observed it): cells with such a corner have no
// surface, like cells with an unstored corner. Far below any finite density or distance a map
// holds, and tested with a comparison, not isnan, so fast-math builds keep the test.
inline constexpr float kIsoNoValue = -3.0e38f;
PLX_HD bool IsoHasValue(float v) { return v > kIsoNoValue; }

enum class MeshColorMode : int {
  kDc = 0,           // the view-independent SH term (as the point export)
  kViewAlongNormal,  // the colour a camera looking at the vertex against its normal would see
};

struct IsoSurfaceParams {
  float iso_level = 0.0f;  // density (1/m); a cell corner is inside when its density is above
  MeshColorMode color_mode = MeshColorMode::kDc;
  const MarchingCubesTable* table = nullptr;  // in memory the backend reads
  // The cells meshed, by their lowest corners' vertex coordinates in the grid's index
  // (inclusive): a region of the map (core/mesh/iso_surface.h). Cells outside have no
  // triangles, so the triangles of neighbouring regions never overlap. Everything by default.
  int32_t cell_min[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
  int32_t cell_max[3] = {INT32_MAX, INT32_MAX, INT32_MAX};
};

// Which bricks' cells a marching-cubes call visits. Without a list (slots null), work item i is
// the cell whose lowest corner is stored vertex i (every brick in slot order). With one, item i
// is local cell i % 512 of the brick in slot slots[i / 512]: a region's bricks only, so its
// cost does not grow with the rest of the map. A slot outside the grid has no cells.
struct IsoBrickList {
  const int32_t* slots = nullptr;  // [count], in memory the backend reads
  int64_t count = 0;
};

// The stored vertex (slot * 512 + local) of work item `item` (see IsoBrickList), or -1.
PLX_HD int64_t IsoWorkVertex(const GridView& g, const IsoBrickList& bricks, int64_t item) {
  if (bricks.slots == nullptr) return item;
  const int64_t slot = bricks.slots[item / kBrickVertices];
  if (slot < 0 || slot >= g.num_bricks) return -1;
  return slot * kBrickVertices + item % kBrickVertices;
}

// Density of vertex (vx, vy, vz), 0 when it is not stored.
PLX_HD float IsoVertexDensity(const GridView& g, int vx, int vy, int vz) {
  const int64_t slot = g.VertexSlot(vx, vy, vz);
  return slot < 0 ? 0.0f : g.Density(slot);
}

// The case (inside-corner mask) of the cell whose lowest corner is stored vertex `vertex`, or
// -1 when there is no such vertex (-1), a corner is not stored or the cell is outside the
// params' cell range. `cell` gets the corner's vertex coordinates.
PLX_HD int IsoCellCase(const GridView& g, int64_t vertex, const IsoSurfaceParams& p,
                       int cell[3]) {
  if (vertex < 0) return -1;
  g.VertexCoords(vertex, cell);
  for (int a = 0; a < 3; ++a) {
    if (cell[a] < p.cell_min[a] || cell[a] > p.cell_max[a]) return -1;
  }
  int mask = 0;
  for (int k = 0; k < 8; ++k) {
    const int64_t slot = g.VertexSlot(cell[0] + (k & 1), cell[1] + ((k >> 1) & 1),
                                      cell[2] + ((k >> 2) & 1));
    if (slot < 0) return -1;
    const float value = g.Density(slot);
    if (!IsoHasValue(value)) return -1;
    if (value > p.iso_level) mask |= 1 << k;
  }
  return mask;
}

PLX_HD int64_t IsoEdgeKey(const GridView& g, const int low[3], int axis) {
  const int64_t ex = g.vertex_extent(0), ey = g.vertex_extent(1);
  return ((low[2] * ey + low[1]) * ex + low[0]) * 3 + axis;
}

PLX_HD void DecodeIsoEdgeKey(const GridView& g, int64_t key, int low[3], int* axis) {
  const int64_t ex = g.vertex_extent(0), ey = g.vertex_extent(1);
  *axis = static_cast<int>(key % 3);
  const int64_t r = key / 3;
  low[0] = static_cast<int>(r % ex);
  low[1] = static_cast<int>((r / ex) % ey);
  low[2] = static_cast<int>(r / (ex * ey));
}

// Edge key of cube edge e of the cell with lowest corner `cell`.
PLX_HD int64_t IsoCellEdgeKey(const GridView& g, const int cell[3], int e) {
  const int corner = CubeEdgeLowCorner(e);
  const int low[3] = {cell[0] + (corner & 1), cell[1] + ((corner >> 1) & 1),
                      cell[2] + ((corner >> 2) & 1)};
  return IsoEdgeKey(g, low, CubeEdgeAxis(e));
}

// Central-difference density gradient at vertex v (per voxel; only its direction is used). A
// neighbour without a value (kIsoNoValue) makes it one-sided: the vertex's own value stands in.
PLX_HD Vec3f IsoVertexGradient(const GridView& g, const int v[3]) {
  const float centre = IsoVertexDensity(g, v[0], v[1], v[2]);
  float d[3];
  for (int a = 0; a < 3; ++a) {
    int lo[3] = {v[0], v[1], v[2]}, hi[3] = {v[0], v[1], v[2]};
    lo[a] -= 1;
    hi[a] += 1;
    float up = IsoVertexDensity(g, hi[0], hi[1], hi[2]);
    float down = IsoVertexDensity(g, lo[0], lo[1], lo[2]);
    if (!IsoHasValue(up)) up = centre;
    if (!IsoHasValue(down)) down = centre;
    d[a] = 0.5f * (up - down);
  }
  return {d[0], d[1], d[2]};
}

struct IsoVertex {
  Vec3f position;
  Vec3f normal;  // unit, towards falling density; zero when the gradient vanishes
  uint8_t color[3];
  // Some SH coefficient of the edge's ends is non-zero: a keyframe saw the surface here.
  // Fusion colours every vertex near a measured surface and optimisation moves the SH of every
  // vertex a training ray reaches, so all-zero SH marks a surface no view saw, such as the back
  // of a wall where fusion's truncation ends the solid.
  bool observed;
};

// The mesh vertex on the edge `key`: where the density, linear along the edge (it is, between
// two vertices of a trilinear field), crosses the iso-level. The normal is the central-difference
// gradients of the two ends blended with the same weights, negated (smooth across cells, unlike
// the trilinear gradient, which jumps at cell faces). The colour blends the ends' SH weighted by
// interpolation weight times density, as compositing weights colour by density: the outside end
// is free space whose colour the map barely constrains.
PLX_HD IsoVertex ComputeIsoVertex(const GridView& g, int64_t key, const IsoSurfaceParams& p) {
  int a[3], axis = 0;
  DecodeIsoEdgeKey(g, key, a, &axis);
  int b[3] = {a[0], a[1], a[2]};
  b[axis] += 1;
  const int64_t slot_a = g.VertexSlot(a[0], a[1], a[2]);
  const int64_t slot_b = g.VertexSlot(b[0], b[1], b[2]);
  const float da = slot_a < 0 ? 0.0f : g.Density(slot_a);
  const float db = slot_b < 0 ? 0.0f : g.Density(slot_b);
  // The ends are on opposite sides of the level, so the denominator is not zero.
  float t = (p.iso_level - da) / (db - da);
  t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
  IsoVertex out;
  const Vec3f pa = g.VertexPosition(a[0], a[1], a[2]);
  out.position = pa;
  const float shift = t * g.voxel_size;
  if (axis == 0) out.position.x += shift;
  if (axis == 1) out.position.y += shift;
  if (axis == 2) out.position.z += shift;

  const Vec3f grad = IsoVertexGradient(g, a) * (1.0f - t) + IsoVertexGradient(g, b) * t;
  const float norm = Norm(grad);
  out.normal = norm > 1e-12f ? grad * (-1.0f / norm) : Vec3f{0.0f, 0.0f, 0.0f};

  float wa = (1.0f - t) * (da > 0.0f ? da : 0.0f);
  float wb = t * (db > 0.0f ? db : 0.0f);
  if (!(wa + wb > 0.0f)) {
    wa = 1.0f - t;
    wb = t;
  }
  float sh[kShCoeffCount];
  out.observed = false;
  for (int j = 0; j < kShCoeffCount; ++j) {
    const float va = slot_a < 0 ? 0.0f : g.Sh(slot_a)[j];
    const float vb = slot_b < 0 ? 0.0f : g.Sh(slot_b)[j];
    out.observed = out.observed || va != 0.0f || vb != 0.0f;
    sh[j] = (wa * va + wb * vb) / (wa + wb);
  }
  float basis[kShBasisCount];
  const bool along_normal = p.color_mode == MeshColorMode::kViewAlongNormal && norm > 1e-12f;
  EvalShBasis(-out.normal, basis);
  for (int c = 0; c < 3; ++c) {
    float raw = basis[0] * sh[c * kShBasisCount];
    if (along_normal) {
      for (int k = 1; k < kShBasisCount; ++k) raw += basis[k] * sh[c * kShBasisCount + k];
    }
    float v = raw + 0.5f;
    v = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
    out.color[c] = static_cast<uint8_t>(v * 255.0f + 0.5f);
  }
  return out;
}

}  // namespace plx

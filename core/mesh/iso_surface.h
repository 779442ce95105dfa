// A triangle mesh of the map's surface: marching cubes on the density field at an iso-level,
// run on a backend (the per-cell and per-vertex work, core/kernels/marching_cubes.h), with
// vertices on shared cell edges merged, optional removal of small floating components, normals
// from the density gradient and colours from the SH coefficients.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/geometry/axis_box.h"
#include "core/geometry/triangle_mesh.h"
#include "core/grid/sparse_grid.h"
#include "core/kernels/backend.h"
#include "core/kernels/marching_cubes.h"

namespace plx {

// Density (1/m) of the surface when the caller names none. Depth-guided initialisation puts a
// fused surface at sigma_max / 2 = 100/m, and optimisation moves it; on a mapped synthetic room
// 50/m scored best of the levels tried, well above the point export's 5/m, whose surface sits
// in the soft front of the density ramp (the numbers: docs/BENCHMARKS.md, "Mesh export").
inline constexpr float kDefaultMeshIsoLevel = 50.0f;
// Enough for a large room at 1 cm (about 10 M triangles); each costs about 60 bytes while it
// is built.
inline constexpr int64_t kDefaultMaxMeshTriangles = 20'000'000;

struct MeshOptions {
  float iso_level = kDefaultMeshIsoLevel;  // > 0: unstored space reads 0 and must be outside
  // Connected components (triangles sharing vertices) with fewer triangles are dropped: the
  // floaters that a few wrong depth pixels leave in free space. 0 keeps everything.
  int64_t min_component_triangles = 0;
  MeshColorMode color_mode = MeshColorMode::kDc;
  // False drops the triangles no view saw (IsoVertex::observed): mostly the back faces of walls
  // and boxes, where depth fusion's truncation ends the solid a few centimetres behind the
  // surface. Rendering never reaches them, but an iso-surface has them. True keeps them.
  bool keep_unobserved = false;
  // More triangles than this fails with RESOURCE_EXHAUSTED before they are all built.
  int64_t max_triangles = kDefaultMaxMeshTriangles;
  // Only this box of the map (world coordinates, metres), e.g. the room a headset is in; unset
  // = the whole map. Only the bricks with cells in the box are visited, so the work grows with
  // the box, not the map. A triangle is kept whole, never clipped: the mesh has the triangles
  // of the cells whose centres lie in [min, max) on every axis, so it reaches at most half a
  // voxel past the box, every vertex is one the full mesh has (same position, normal, colour;
  // only the rare vertex without a density gradient takes its normal from the triangles kept),
  // and boxes that share a face tile the map: each triangle in exactly one of them, meeting
  // at shared vertices (without min_component_triangles, which judges the pieces the box cut).
  // The filters (keep_unobserved, min_component_triangles) and the triangle limit then apply
  // to the region's mesh. A box with no surface in it gives an empty mesh, not an error:
  // "nothing mapped here yet" is an answer a client can act on.
  std::optional<AxisBox> region;
};

// The slots of the bricks of `grid` holding a cell whose centre lies in `box` (the bricks a
// region's mesh visits, MeshOptions::region), in slot order.
std::vector<int32_t> BricksWithCellsIn(const SparseGrid& grid, const AxisBox& box);

// InvalidArgument naming the field (iso_level, min_component_triangles, max_triangles,
// region: CheckAxisBox).
absl::Status ValidateMeshOptions(const MeshOptions& options);

// The mesh of `grid`. Work is done in slices of bricks; `cancelled` is asked between slices and
// true stops with CANCELLED. Out of memory is RESOURCE_EXHAUSTED, as is a mesh over
// options.max_triangles. Arrays the backend reads are UnifiedVectors made here, so a CUDA
// backend works as long as the grid is in memory it reads (the programs' rule, backend.h).
absl::StatusOr<TriangleMesh> ExtractMesh(const SparseGrid& grid, Backend& backend,
                                         const MeshOptions& options,
                                         const std::function<bool()>& cancelled = nullptr);

// The mesh of another field in `grid`'s layout at `level` (a cell corner is inside when its
// value is above it): `field` is grid's view with the field's per-brick tables as its density
// (SparseGrid::ViewOf), so colours still come from the grid's SH. Vertices holding
// kIsoNoValue have no value; cells touching one have no surface. ExtractMesh is this with the
// density at options.iso_level; here options.iso_level is not used (but still validated).
absl::StatusOr<TriangleMesh> ExtractFieldMesh(const SparseGrid& grid, const GridView& field,
                                              float level, Backend& backend,
                                              const MeshOptions& options,
                                              const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

// A triangle mesh of the map's surface: marching cubes on the density field at an iso-level,
// run on a backend (the per-cell and per-vertex work, core/kernels/marching_cubes.h), with
// vertices on shared cell edges merged, optional removal of small floating components, normals
// from the density gradient and colours from the SH coefficients.
#pragma once

#include <cstdint>
#include <functional>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
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
};

// InvalidArgument naming the field (iso_level, min_component_triangles, max_triangles).
absl::Status ValidateMeshOptions(const MeshOptions& options);

// The mesh of `grid`. Work is done in slices of bricks; `cancelled` is asked between slices and
// true stops with CANCELLED. Out of memory is RESOURCE_EXHAUSTED, as is a mesh over
// options.max_triangles. Arrays the backend reads are UnifiedVectors made here, so a CUDA
// backend works as long as the grid is in memory it reads (the programs' rule, backend.h).
absl::StatusOr<TriangleMesh> ExtractMesh(const SparseGrid& grid, Backend& backend,
                                         const MeshOptions& options,
                                         const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

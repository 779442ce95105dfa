// A map as one PLY file in either form that `plenox export` and the daemon's Export offer: the
// coloured points on the surface of the density field (core/formats/ply_export.h) or a triangle
// mesh by marching cubes (core/mesh/iso_surface.h, core/formats/ply_mesh.h). Both callers build
// it here, so the same spec gives the same file in-process and on the daemon.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/statusor.h"
#include "core/formats/ply_export.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mesh/iso_surface.h"

namespace plx {

// Which file to make. The defaults are core's: a point cloud above kDefaultExportMinDensity, or
// a mesh with MeshOptions' defaults (kDefaultMeshIsoLevel, kDefaultMaxMeshTriangles).
struct ExportSpec {
  bool mesh = false;                             // false: points
  float min_density = kDefaultExportMinDensity;  // points only
  MeshOptions mesh_options;                      // mesh only
};

struct MapPly {
  std::string bytes;
  int64_t vertices = 0;  // the points, or the mesh's vertices
  int64_t faces = 0;     // the mesh's triangles; 0 for points
};

// The PLY file of `map` as `spec` asks. The mesh runs on `backend` (the points need none).
// `cancelled` is asked as the work goes on; true stops it with CANCELLED. RESOURCE_EXHAUSTED out
// of memory or over the mesh's triangle limit; INVALID_ARGUMENT for mesh options that
// ValidateMeshOptions refuses.
absl::StatusOr<MapPly> ExportMapPly(const ExportSpec& spec, const PlenoxelMap& map,
                                    Backend& backend,
                                    const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

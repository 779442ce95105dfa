#include "core/export/map_export.h"

#include <utility>

#include "core/formats/ply_mesh.h"

namespace plx {

absl::StatusOr<MapPly> ExportMapPly(const ExportSpec& spec, const PlenoxelMap& map,
                                    Backend& backend, const std::function<bool()>& cancelled) {
  if (!spec.mesh) {
    absl::StatusOr<PlyExport> points = ExportSurfacePointsPly(map, spec.min_density, cancelled);
    if (!points.ok()) return points.status();
    return MapPly{std::move(points->bytes), points->points, 0};
  }
  absl::StatusOr<TriangleMesh> mesh = ExtractMesh(map.grid, backend, spec.mesh_options, cancelled);
  if (!mesh.ok()) return mesh.status();
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(*mesh, map.source);
  if (!ply.ok()) return ply.status();
  return MapPly{std::move(ply->bytes), ply->vertices, ply->faces};
}

}  // namespace plx

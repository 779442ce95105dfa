#include "core/export/map_export.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "core/formats/glb_mesh.h"
#include "core/formats/ply_mesh.h"
#include "core/mesh/mesh_simplify.h"
#include "core/mesh/observed_surface.h"

namespace plx {
namespace {

absl::StatusOr<MapExport> EncodeMesh(const ExportSpec& spec, const TriangleMesh& mesh,
                                     const std::string& source, int64_t full_faces,
                                     double lod_error_m) {
  MapExport out;
  out.full_faces = full_faces;
  out.lod_error_m = lod_error_m;
  if (spec.mesh_format == MeshFileFormat::kGlb) {
    GlbMeshMetadata metadata;
    metadata.source = source;
    metadata.full_triangles = full_faces;
    metadata.lod_error_m = lod_error_m;
    metadata.region = spec.mesh_options.region;
    absl::StatusOr<GlbMesh> glb = EncodeGlbMesh(mesh, metadata);
    if (!glb.ok()) return glb.status();
    out.bytes = std::move(glb->bytes);
    out.vertices = glb->vertices;
    out.faces = glb->faces;
    return out;
  }
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(mesh, source, spec.mesh_options.region);
  if (!ply.ok()) return ply.status();
  out.bytes = std::move(ply->bytes);
  out.vertices = ply->vertices;
  out.faces = ply->faces;
  return out;
}

}  // namespace

const char* MeshSurfaceName(MeshSurface surface) {
  switch (surface) {
    case MeshSurface::kAuto:
      return "auto";
    case MeshSurface::kObserved:
      return "observed";
    case MeshSurface::kDensity:
      return "density";
  }
  return "unknown";
}

absl::StatusOr<MeshSurface> MeshSurfaceFromName(absl::string_view name) {
  for (MeshSurface s : {MeshSurface::kAuto, MeshSurface::kObserved, MeshSurface::kDensity}) {
    if (name == MeshSurfaceName(s)) return s;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "expected auto, observed or density, got \"", name.substr(0, 100), "\""));
}

absl::StatusOr<TriangleMesh> ExtractMapMesh(const PlenoxelMap& map, const MapKeyframes& keyframes,
                                            MeshSurface surface, Backend& backend,
                                            const MeshOptions& options,
                                            const std::function<bool()>& cancelled) {
  const bool observed = surface == MeshSurface::kObserved ||
                        (surface == MeshSurface::kAuto && !keyframes.empty());
  if (observed) return ExtractObservedMesh(map, keyframes, backend, options, {}, cancelled);
  return ExtractMesh(map.grid, backend, options, cancelled);
}

absl::Status ValidateExportSpec(const ExportSpec& spec) {
  if (spec.lod_triangles < 0 || spec.lod_triangles > kMaxLodTriangles) {
    return absl::InvalidArgumentError(absl::StrCat("lod_triangles: must be in [0, ",
                                                   kMaxLodTriangles, "] (0 = the full mesh), got ",
                                                   spec.lod_triangles));
  }
  if (spec.mesh_surface != MeshSurface::kAuto && spec.mesh_surface != MeshSurface::kObserved &&
      spec.mesh_surface != MeshSurface::kDensity) {
    return absl::InvalidArgumentError("mesh_surface: unknown");
  }
  if (spec.mesh_format != MeshFileFormat::kPly && spec.mesh_format != MeshFileFormat::kGlb) {
    return absl::InvalidArgumentError("mesh_format: unknown");
  }
  if (!spec.mesh) {
    if (spec.mesh_format != MeshFileFormat::kPly) {
      return absl::InvalidArgumentError("mesh_format: glTF holds meshes only, not points");
    }
    if (spec.lod_triangles != 0) {
      return absl::InvalidArgumentError("lod_triangles: applies to meshes only");
    }
    if (spec.mesh_options.region) {
      return absl::InvalidArgumentError("region: applies to meshes only");
    }
    if (spec.mesh_surface != MeshSurface::kAuto) {
      return absl::InvalidArgumentError("mesh_surface: applies to meshes only");
    }
    return absl::OkStatus();
  }
  return ValidateMeshOptions(spec.mesh_options);
}

absl::StatusOr<MapExport> ExportMap(const ExportSpec& spec, const PlenoxelMap& map,
                                    const MapKeyframes& keyframes, Backend& backend,
                                    const std::function<bool()>& cancelled) {
  if (absl::Status s = ValidateExportSpec(spec); !s.ok()) return s;
  if (!spec.mesh) {
    absl::StatusOr<PlyExport> points = ExportSurfacePointsPly(map, spec.min_density, cancelled);
    if (!points.ok()) return points.status();
    MapExport out;
    out.bytes = std::move(points->bytes);
    out.vertices = points->points;
    return out;
  }
  absl::StatusOr<TriangleMesh> mesh =
      ExtractMapMesh(map, keyframes, spec.mesh_surface, backend, spec.mesh_options, cancelled);
  if (!mesh.ok()) return mesh.status();
  const int64_t full_faces = mesh->num_triangles();
  if (spec.lod_triangles == 0 || full_faces <= spec.lod_triangles) {
    return EncodeMesh(spec, *mesh, map.source, full_faces, 0.0);
  }
  absl::StatusOr<SimplifiedMesh> lod = SimplifyMesh(*mesh, spec.lod_triangles, cancelled);
  if (!lod.ok()) return lod.status();
  *mesh = TriangleMesh();  // the full mesh is no longer needed while the file is written
  return EncodeMesh(spec, lod->mesh, map.source, full_faces, lod->error_m);
}

}  // namespace plx

#include "server/export_request.h"

#include <cmath>
#include <cstdint>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/formats/ply_export.h"
#include "core/formats/ply_mesh.h"

namespace plx::server {
namespace pb = ::plenoxd::v1;

absl::StatusOr<ExportSpec> ParseExportRequest(const pb::ExportRequest& request) {
  ExportSpec spec;
  if (!pb::ExportFormat_IsValid(request.format())) {
    return absl::InvalidArgumentError(
        absl::StrCat("format: unknown value ", request.format(), " (POINTS or MESH)"));
  }
  spec.mesh = request.format() == pb::EXPORT_FORMAT_MESH;
  // Exactly 0 means the default; a negative or non-finite value is a client's mistake, not a
  // request for the default.
  if (!(std::isfinite(request.min_density()) && request.min_density() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "min_density: must be finite and >= 0 (0 = the default, ", kDefaultExportMinDensity,
        "), got ", request.min_density()));
  }
  if (!(std::isfinite(request.iso_level()) && request.iso_level() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "iso_level: must be finite and >= 0 (0 = the default, ", kDefaultMeshIsoLevel,
        "), got ", request.iso_level()));
  }
  if (!spec.mesh) {
    const char* mesh_field = request.iso_level() != 0                 ? "iso_level"
                             : request.min_component_triangles() != 0 ? "min_component_triangles"
                             : request.max_triangles() != 0           ? "max_triangles"
                             : request.keep_unobserved()              ? "keep_unobserved"
                             : request.mesh_color() != 0              ? "mesh_color"
                                                                      : nullptr;
    if (mesh_field != nullptr) {
      return absl::InvalidArgumentError(
          absl::StrCat(mesh_field, ": applies to format MESH only"));
    }
    spec.min_density =
        request.min_density() > 0 ? request.min_density() : kDefaultExportMinDensity;
    return spec;
  }
  if (request.min_density() != 0) {
    return absl::InvalidArgumentError(
        "min_density: applies to format POINTS only (a mesh takes iso_level)");
  }
  if (!pb::MeshColor_IsValid(request.mesh_color())) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh_color: unknown value ", request.mesh_color()));
  }
  if (request.max_triangles() > static_cast<uint64_t>(kDefaultMaxMeshTriangles)) {
    return absl::InvalidArgumentError(absl::StrCat("max_triangles: at most ",
                                                   kDefaultMaxMeshTriangles, " (0 = that), got ",
                                                   request.max_triangles()));
  }
  // Above the triangle limit the filter could not keep anything anyway.
  if (request.min_component_triangles() > static_cast<uint64_t>(kDefaultMaxMeshTriangles)) {
    return absl::InvalidArgumentError(absl::StrCat("min_component_triangles: at most ",
                                                   kDefaultMaxMeshTriangles, ", got ",
                                                   request.min_component_triangles()));
  }
  MeshOptions& o = spec.mesh_options;
  if (request.iso_level() > 0) o.iso_level = request.iso_level();
  o.min_component_triangles = static_cast<int64_t>(request.min_component_triangles());
  if (request.max_triangles() > 0) o.max_triangles = static_cast<int64_t>(request.max_triangles());
  o.keep_unobserved = request.keep_unobserved();
  o.color_mode = request.mesh_color() == pb::MESH_COLOR_ALONG_NORMAL
                     ? MeshColorMode::kViewAlongNormal
                     : MeshColorMode::kDc;
  if (absl::Status s = ValidateMeshOptions(o); !s.ok()) return s;
  return spec;
}

absl::StatusOr<std::string> BuildExport(const ExportSpec& spec, const PlenoxelMap& map,
                                        Backend& backend, const std::function<bool()>& cancelled) {
  if (!spec.mesh) {
    absl::StatusOr<PlyExport> ply = ExportSurfacePointsPly(map, spec.min_density, cancelled);
    if (!ply.ok()) return ply.status();
    return std::move(ply->bytes);
  }
  absl::StatusOr<TriangleMesh> mesh = ExtractMesh(map.grid, backend, spec.mesh_options, cancelled);
  if (!mesh.ok()) return mesh.status();
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(*mesh, map.source);
  if (!ply.ok()) return ply.status();
  return std::move(ply->bytes);
}

}  // namespace plx::server

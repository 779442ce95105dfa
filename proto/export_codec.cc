#include "proto/export_codec.h"

#include <cmath>
#include <cstdint>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// The first mesh-only field a point export sets, or null when it sets none.
const char* MeshFieldSetOnPoints(const pb::ExportRequest& request) {
  if (request.iso_level() != 0) return "iso_level";
  if (request.min_component_triangles() != 0) return "min_component_triangles";
  if (request.max_triangles() != 0) return "max_triangles";
  if (request.keep_unobserved()) return "keep_unobserved";
  if (request.mesh_color() != 0) return "mesh_color";
  if (request.lod_triangles() != 0) return "lod_triangles";
  if (request.has_region()) return "region";
  if (request.mesh_surface() != pb::MESH_SURFACE_AUTO) return "mesh_surface";
  return nullptr;
}

absl::StatusOr<MeshOptions> MeshOptionsFromProto(const pb::ExportRequest& request) {
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
  if (request.lod_triangles() > static_cast<uint64_t>(kMaxLodTriangles)) {
    return absl::InvalidArgumentError(absl::StrCat("lod_triangles: at most ", kMaxLodTriangles,
                                                   " (0 = the full mesh), got ",
                                                   request.lod_triangles()));
  }
  // Above the triangle limit the filter could not keep anything anyway.
  if (request.min_component_triangles() > static_cast<uint64_t>(kDefaultMaxMeshTriangles)) {
    return absl::InvalidArgumentError(absl::StrCat("min_component_triangles: at most ",
                                                   kDefaultMaxMeshTriangles, ", got ",
                                                   request.min_component_triangles()));
  }
  MeshOptions o;
  if (request.iso_level() > 0) o.iso_level = request.iso_level();
  o.min_component_triangles = static_cast<int64_t>(request.min_component_triangles());
  if (request.max_triangles() > 0) o.max_triangles = static_cast<int64_t>(request.max_triangles());
  o.keep_unobserved = request.keep_unobserved();
  o.color_mode = request.mesh_color() == pb::MESH_COLOR_ALONG_NORMAL
                     ? MeshColorMode::kViewAlongNormal
                     : MeshColorMode::kDc;
  if (request.has_region()) {
    const pb::BoundingBox& r = request.region();
    o.region = AxisBox{{r.min_x(), r.min_y(), r.min_z()}, {r.max_x(), r.max_y(), r.max_z()}};
  }
  // Names "region: ..." for a box that is not finite or has min >= max on an axis.
  if (absl::Status s = ValidateMeshOptions(o); !s.ok()) return s;
  return o;
}

}  // namespace

absl::StatusOr<ExportSpec> ExportSpecFromProto(const pb::ExportRequest& request) {
  if (!pb::ExportFormat_IsValid(request.format())) {
    return absl::InvalidArgumentError(
        absl::StrCat("format: unknown value ", request.format(), " (POINTS, MESH or MESH_GLB)"));
  }
  // Exactly 0 means the default; a negative or non-finite value is a client's mistake, not a
  // request for the default.
  if (!(std::isfinite(request.min_density()) && request.min_density() >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_density: must be finite and >= 0 (0 = the default, ",
                     kDefaultExportMinDensity, "), got ", request.min_density()));
  }
  if (!(std::isfinite(request.iso_level()) && request.iso_level() >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("iso_level: must be finite and >= 0 (0 = the default, ", kDefaultMeshIsoLevel,
                     "), got ", request.iso_level()));
  }
  ExportSpec spec;
  spec.mesh = request.format() != pb::EXPORT_FORMAT_POINTS;
  if (spec.mesh) {
    absl::StatusOr<MeshOptions> mesh_options = MeshOptionsFromProto(request);
    if (!mesh_options.ok()) return mesh_options.status();
    spec.mesh_options = *mesh_options;
    spec.mesh_format = request.format() == pb::EXPORT_FORMAT_MESH_GLB ? MeshFileFormat::kGlb
                                                                       : MeshFileFormat::kPly;
    spec.lod_triangles = static_cast<int64_t>(request.lod_triangles());
    switch (request.mesh_surface()) {
      case pb::MESH_SURFACE_AUTO:
        spec.mesh_surface = MeshSurface::kAuto;
        break;
      case pb::MESH_SURFACE_OBSERVED:
        spec.mesh_surface = MeshSurface::kObserved;
        break;
      case pb::MESH_SURFACE_DENSITY:
        spec.mesh_surface = MeshSurface::kDensity;
        break;
      default:
        return absl::InvalidArgumentError(
            absl::StrCat("mesh_surface: unknown value ", request.mesh_surface(),
                         " (AUTO, OBSERVED or DENSITY)"));
    }
    return spec;
  }
  if (const char* mesh_field = MeshFieldSetOnPoints(request); mesh_field != nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(mesh_field, ": applies to formats MESH and MESH_GLB only"));
  }
  if (request.min_density() > 0) spec.min_density = request.min_density();
  return spec;
}

pb::ExportRequest ExportSpecToProto(const ExportSpec& spec) {
  pb::ExportRequest request;
  if (!spec.mesh) {
    request.set_format(pb::EXPORT_FORMAT_POINTS);
    request.set_min_density(spec.min_density);
    return request;
  }
  const MeshOptions& o = spec.mesh_options;
  request.set_format(spec.mesh_format == MeshFileFormat::kGlb ? pb::EXPORT_FORMAT_MESH_GLB
                                                              : pb::EXPORT_FORMAT_MESH);
  request.set_iso_level(o.iso_level);
  request.set_min_component_triangles(static_cast<uint64_t>(o.min_component_triangles));
  request.set_max_triangles(static_cast<uint64_t>(o.max_triangles));
  request.set_keep_unobserved(o.keep_unobserved);
  request.set_mesh_color(o.color_mode == MeshColorMode::kViewAlongNormal
                             ? pb::MESH_COLOR_ALONG_NORMAL
                             : pb::MESH_COLOR_DC);
  request.set_lod_triangles(static_cast<uint64_t>(spec.lod_triangles));
  request.set_mesh_surface(spec.mesh_surface == MeshSurface::kObserved ? pb::MESH_SURFACE_OBSERVED
                           : spec.mesh_surface == MeshSurface::kDensity
                               ? pb::MESH_SURFACE_DENSITY
                               : pb::MESH_SURFACE_AUTO);
  if (o.region) {
    pb::BoundingBox* r = request.mutable_region();
    r->set_min_x(o.region->min[0]);
    r->set_min_y(o.region->min[1]);
    r->set_min_z(o.region->min[2]);
    r->set_max_x(o.region->max[0]);
    r->set_max_y(o.region->max[1]);
    r->set_max_z(o.region->max[2]);
  }
  return request;
}

}  // namespace plx

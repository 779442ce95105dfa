#include "web/viewer_mesh.h"

#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/formats/glb_mesh.h"
#include "core/formats/ply_mesh.h"
#include "core/export/map_export.h"
#include "core/mesh/iso_surface.h"
#include "core/mesh/mesh_simplify.h"

namespace plx::web {

absl::StatusOr<ViewerMesh> BuildViewerMesh(ViewerSource& source, const ViewerMap& map,
                                           int64_t max_triangles, absl::Duration timeout,
                                           const std::optional<AxisBox>& region) {
  if (max_triangles <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_mesh_triangles: must be > 0, got ", max_triangles));
  }
  // The Export RPC's defaults: the observed surface when the version has keyframes (else the
  // density's at 50/m), DC colours, seen faces.
  MeshOptions options;
  options.max_triangles = max_triangles;
  options.region = region;
  if (absl::Status s = ValidateMeshOptions(options); !s.ok()) return s;
  absl::StatusOr<TriangleMesh> mesh = absl::UnknownError("not built");
  const absl::Status ran = source.RunOnDevice(
      [&](Backend& backend, const std::function<bool()>& cancelled) {
        static const MapKeyframes kNone;
        mesh = ExtractMapMesh(*map.map, map.keyframes ? *map.keyframes : kNone,
                              MeshSurface::kAuto, backend, options, cancelled);
        return mesh.status();
      },
      timeout);
  ViewerMesh out;
  if (!ran.ok()) {
    // ExtractMesh stops as soon as a slice would pass the cap (before building it), so a map too
    // large for the viewer costs one partial pass. Its over-cap errors say "the mesh has more
    // than" (triangles, or 2^31 vertices); out of memory is RESOURCE_EXHAUSTED too, but a
    // passing condition, so it is returned (503) and not kept.
    if (absl::IsResourceExhausted(ran) &&
        absl::StartsWith(ran.message(), "the mesh has more than")) {
      out.too_large = absl::StrCat(
          "the mesh of this ", region ? "region of the " : "", "map version has more than ",
          max_triangles, " triangles, the viewer's limit; ",
          region ? "ask for a smaller box or " : "", "export it instead (plenox export --mesh)");
      return out;
    }
    return ran;
  }
  absl::StatusOr<PlyMesh> ply = EncodePlyMesh(*mesh, map.map->source, region);
  if (!ply.ok()) return ply.status();
  out.ply = std::move(ply->bytes);
  out.vertices = ply->vertices;
  out.faces = ply->faces;
  out.mesh = std::move(*mesh);
  out.region = region;
  return out;
}

absl::StatusOr<ViewerGlb> BuildViewerGlb(const ViewerMesh& mesh, const std::string& source_text,
                                         int64_t triangles) {
  ViewerGlb out;
  if (!mesh.too_large.empty()) {
    out.too_large = mesh.too_large;
    return out;
  }
  out.full_faces = mesh.mesh.num_triangles();
  GlbMeshMetadata metadata;
  metadata.source = source_text;
  metadata.full_triangles = out.full_faces;
  metadata.region = mesh.region;
  absl::StatusOr<GlbMesh> glb = absl::UnknownError("not written");
  if (triangles <= 0 || triangles >= out.full_faces) {
    glb = EncodeGlbMesh(mesh.mesh, metadata);
  } else {
    absl::StatusOr<SimplifiedMesh> lod = SimplifyMesh(mesh.mesh, triangles);
    if (!lod.ok()) return lod.status();
    out.lod_error_m = lod->error_m;
    metadata.lod_error_m = lod->error_m;
    glb = EncodeGlbMesh(lod->mesh, metadata);
  }
  if (!glb.ok()) return glb.status();
  out.glb = std::move(glb->bytes);
  out.vertices = glb->vertices;
  out.faces = glb->faces;
  return out;
}

absl::StatusOr<std::shared_ptr<const ViewerMesh>> MeshCache::Get(ViewerSource& source,
                                                                 const std::string& name,
                                                                 const ViewerMap& map) {
  return cache_.Get(name, map.version, [&] {
    return BuildViewerMesh(source, map, max_triangles_, timeout_);
  });
}

absl::StatusOr<std::shared_ptr<const ViewerGlb>> MeshCache::GetGlb(ViewerSource& source,
                                                                   const std::string& name,
                                                                   const ViewerMap& map,
                                                                   int64_t triangles) {
  absl::StatusOr<std::shared_ptr<const ViewerMesh>> mesh = Get(source, name, map);
  if (!mesh.ok()) return mesh.status();
  // Every budget that keeps the whole mesh is the same file: one entry (variant 0).
  const int64_t full = (*mesh)->mesh.num_triangles();
  const int64_t variant = triangles <= 0 || triangles >= full ? 0 : triangles;
  return glb_cache_.Get(name, variant, map.version, [&] {
    return BuildViewerGlb(**mesh, map.map->source, variant);
  });
}

namespace {

// A cache variant naming `region`: exact coordinates (17 digits), so two boxes share an entry
// only when they are the same.
std::string RegionVariant(const AxisBox& region) {
  return absl::StrFormat("region %.17g %.17g %.17g %.17g %.17g %.17g", region.min[0],
                         region.min[1], region.min[2], region.max[0], region.max[1],
                         region.max[2]);
}

}  // namespace

absl::StatusOr<std::shared_ptr<const ViewerMesh>> MeshCache::GetRegion(ViewerSource& source,
                                                                       const std::string& name,
                                                                       const ViewerMap& map,
                                                                       const AxisBox& region) {
  return cache_.Get(name, RegionVariant(region), map.version, [&] {
    return BuildViewerMesh(source, map, max_triangles_, timeout_, region);
  });
}

absl::StatusOr<std::shared_ptr<const ViewerGlb>> MeshCache::GetRegionGlb(
    ViewerSource& source, const std::string& name, const ViewerMap& map, int64_t triangles,
    const AxisBox& region) {
  const std::string variant = absl::StrFormat("%s, %d triangles", RegionVariant(region),
                                              triangles);
  return glb_cache_.Get(name, variant, map.version,
                        [&]() -> absl::StatusOr<ViewerGlb> {
    absl::StatusOr<ViewerMesh> mesh =
        BuildViewerMesh(source, map, max_triangles_, timeout_, region);
    if (!mesh.ok()) return mesh.status();
    return BuildViewerGlb(*mesh, map.map->source, triangles);
  });
}

}  // namespace plx::web

// The viewer's meshes: marching cubes on a published map version (core/mesh/iso_surface.h, with
// the Export RPC's defaults), run on the source's compute device, capped at a triangle count,
// and cached per (map, version) like the point clouds (web/point_cloud_cache.h); and the same
// mesh as binary glTF at a level of detail a client names (core/mesh/mesh_simplify.h,
// core/formats/glb_mesh.h), cached per (map, version, triangle budget).
//
// The PLY answer is the binary PLY mesh core/formats/ply_mesh.h writes (float x y z nx ny nz,
// uchar red green blue; `list uchar int` faces): about 27 bytes a vertex and 13 a face, so
// within ~10% of the smallest form that carries normals and colours, and it is the very file
// Export MESH gives: a saved answer opens in MeshLab or Blender, and tests check it with the
// same reader as the export's. The GLB answer is the file Export MESH_GLB gives with
// lod_triangles: what the page loads through three.js's GLTFLoader, and what a headset fetches,
// of the whole map or of a box of it (Export's region, built for that box alone).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/geometry/axis_box.h"
#include "core/geometry/triangle_mesh.h"
#include "web/point_cloud_cache.h"
#include "web/viewer_source.h"

namespace plx::web {

struct ViewerMesh {
  std::string ply;        // empty when too_large
  int64_t vertices = 0;
  int64_t faces = 0;
  TriangleMesh mesh;      // what `ply` holds: the source of the levels of detail
  std::optional<AxisBox> region;  // the box it was cut to (MeshOptions::region); unset: all
  // Set when the map's mesh has more triangles than the cap: the message the page shows (HTTP
  // 413). Kept in the cache like a mesh, so asking again for that version costs nothing.
  std::string too_large;
};

// A level of detail as binary glTF.
struct ViewerGlb {
  std::string glb;        // empty when too_large
  int64_t vertices = 0;
  int64_t faces = 0;
  int64_t full_faces = 0;    // the full mesh's
  double lod_error_m = 0.0;  // SimplifiedMesh::error_m; 0 for the full mesh
  std::string too_large;     // the full mesh's refusal, as ViewerMesh's
};

// Builds `map`'s mesh (of `region` only, when given: only its bricks are meshed) on `source`'s
// device within `timeout`. A mesh over `max_triangles` is a ViewerMesh with too_large set, not
// an error; errors are the device's (DEADLINE_EXCEEDED, UNAVAILABLE while the daemon drains,
// RESOURCE_EXHAUSTED when out of memory).
absl::StatusOr<ViewerMesh> BuildViewerMesh(ViewerSource& source, const ViewerMap& map,
                                           int64_t max_triangles, absl::Duration timeout,
                                           const std::optional<AxisBox>& region = std::nullopt);

// `mesh` as GLB, simplified to at most `triangles` (0 or at least the mesh's count: the full
// mesh), recording the mesh's region. Runs on the calling thread (meshoptimizer on the CPU).
absl::StatusOr<ViewerGlb> BuildViewerGlb(const ViewerMesh& mesh, const std::string& source_text,
                                         int64_t triangles);

class MeshCache {
 public:
  // Meshes kept: each is at most about max_triangles * 27 bytes of PLY (faces and, at most, half
  // as many vertices) and as much again for the mesh it was written from, 54 MB at the viewer's
  // default cap.
  static constexpr size_t kEntries = 2;
  // Levels of detail and regions kept (a page and a headset asking for different budgets or
  // rooms): each at most about max_triangles * 26 bytes of GLB.
  static constexpr size_t kGlbEntries = 2;

  MeshCache(int64_t max_triangles, absl::Duration timeout)
      : max_triangles_(max_triangles), timeout_(timeout), cache_(kEntries),
        glb_cache_(kGlbEntries) {}

  absl::StatusOr<std::shared_ptr<const ViewerMesh>> Get(ViewerSource& source,
                                                        const std::string& name,
                                                        const ViewerMap& map);

  // The mesh of `region` of the map as PLY, built for the region alone like GetRegionGlb's,
  // kept in the same cache as Get's per region.
  absl::StatusOr<std::shared_ptr<const ViewerMesh>> GetRegion(ViewerSource& source,
                                                              const std::string& name,
                                                              const ViewerMap& map,
                                                              const AxisBox& region);

  // The mesh of Get as GLB at `triangles` (0: the full mesh). Budgets at or above the mesh's
  // count share one entry (the full mesh).
  absl::StatusOr<std::shared_ptr<const ViewerGlb>> GetGlb(ViewerSource& source,
                                                          const std::string& name,
                                                          const ViewerMap& map, int64_t triangles);

  // The mesh of `region` of the map as GLB at `triangles`: built on the device for the region
  // alone (a map whose whole mesh is over the cap may still have a room under it), capped at
  // max_triangles like the whole map's, and kept in the levels' cache per (region, budget),
  // so a headset polling its room costs one build per map version.
  absl::StatusOr<std::shared_ptr<const ViewerGlb>> GetRegionGlb(ViewerSource& source,
                                                                const std::string& name,
                                                                const ViewerMap& map,
                                                                int64_t triangles,
                                                                const AxisBox& region);

 private:
  const int64_t max_triangles_;
  const absl::Duration timeout_;
  MapVersionCache<ViewerMesh> cache_;
  MapVersionCache<ViewerGlb> glb_cache_;
};

}  // namespace plx::web

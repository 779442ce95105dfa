// The viewer's meshes: marching cubes on a published map version (core/mesh/iso_surface.h, with
// the Export RPC's defaults), run on the source's compute device, capped at a triangle count,
// and cached per (map, version) like the point clouds (web/point_cloud_cache.h).
//
// The answer is the binary PLY mesh core/formats/ply_mesh.h writes (float x y z nx ny nz, uchar
// red green blue; `list uchar int` faces): about 27 bytes a vertex and 13 a face, so within ~10%
// of the smallest form that carries normals and colours, and it is the very file Export MESH
// gives: the page's PLY reader already reads faces, a saved answer opens in MeshLab or Blender,
// and tests check it with the same reader as the export's. A compact custom form would save a
// little and add a second format to keep in step.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "web/point_cloud_cache.h"
#include "web/viewer_source.h"

namespace plx::web {

struct ViewerMesh {
  std::string ply;        // empty when too_large
  int64_t vertices = 0;
  int64_t faces = 0;
  // Set when the map's mesh has more triangles than the cap: the message the page shows (HTTP
  // 413). Kept in the cache like a mesh, so asking again for that version costs nothing.
  std::string too_large;
};

// Builds `map`'s mesh on `source`'s device within `timeout`. A mesh over `max_triangles` is a
// ViewerMesh with too_large set, not an error; errors are the device's (DEADLINE_EXCEEDED,
// UNAVAILABLE while the daemon drains, RESOURCE_EXHAUSTED when out of memory).
absl::StatusOr<ViewerMesh> BuildViewerMesh(ViewerSource& source, const ViewerMap& map,
                                           int64_t max_triangles, absl::Duration timeout);

class MeshCache {
 public:
  // Meshes kept: each is at most about max_triangles * 27 bytes of PLY (faces and, at most, half
  // as many vertices), 27 MB at the viewer's default cap.
  static constexpr size_t kEntries = 2;

  MeshCache(int64_t max_triangles, absl::Duration timeout)
      : max_triangles_(max_triangles), timeout_(timeout), cache_(kEntries) {}

  absl::StatusOr<std::shared_ptr<const ViewerMesh>> Get(ViewerSource& source,
                                                        const std::string& name,
                                                        const ViewerMap& map);

 private:
  const int64_t max_triangles_;
  const absl::Duration timeout_;
  MapVersionCache<ViewerMesh> cache_;
};

}  // namespace plx::web

// The map viewer's HTTP routes, under /viewer/ of an HttpServer (web/http_server.h):
//
//   /viewer, /viewer/             the page (index.html); /viewer/viewer.js, /viewer/viewer.css
//   /viewer/three/three.min.js    Debian's three.js (web/three_js.h), and
//   /viewer/three/OrbitControls.js  its orbit controls, /viewer/three/GLTFLoader.js its glTF
//                                 loader
//   /viewer/api/maps              JSON: the title and the maps (name, version, bricks, ...)
//   /viewer/api/points?map=M      PLY: M's coloured surface points (web/point_cloud_cache.h)
//   /viewer/api/mesh?map=M[&bbox=XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX]
//                                 PLY: M's triangle mesh with normals and colours
//                                 (web/viewer_mesh.h), of the box alone with bbox (as
//                                 mesh.glb's below); 413 over max_mesh_triangles
//   /viewer/api/mesh.glb?map=M[&triangles=N][&bbox=XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX]
//                                 binary glTF (model/gltf-binary): the same mesh simplified to
//                                 at most N triangles (a level of detail; absent or 0: the full
//                                 mesh); N is 0..max_mesh_triangles (else 400); headers
//                                 X-Faces, X-Full-Faces, X-Lod-Error-M (metres). With bbox only
//                                 that box of the map (metres, map coordinates; Export's region:
//                                 built for the box alone, capped like the whole map's mesh;
//                                 400 unless six finite numbers with min < max)
//   /viewer/api/trajectory?map=M  JSON: M's SLAM cameras (pose, path) and keyframes
//   /viewer/api/render?map=M&...  PNG: M rendered from a pose (web/viewer_render.h)
//
// With a token set, every /viewer/api/ request needs "Authorization: Bearer <token>" (or
// ?token=<token>) and gets 401 without it; the page and scripts carry no map data and are served
// to anyone who reaches the port. Errors: 400 for bad parameters, 404 for unknown maps and
// paths, 413 for a mesh over the triangle cap, 503 while every render slot is busy; the body is
// JSON {"error": "..."}. Every request's work is bounded: renders by size, count and time, point
// clouds by count and a cache, meshes by triangles, time and a cache.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/time/time.h"
#include "web/http_server.h"
#include "web/point_cloud_cache.h"
#include "web/viewer_mesh.h"
#include "web/three_js.h"
#include "web/viewer_source.h"

namespace plx::web {

struct ViewerOptions {
  std::string auth_token;  // empty: no authentication
  // Pixels of one render (also at most kMaxViewerRenderSide a side); plenoxd passes the smaller
  // of this and its --max-render-pixels.
  int64_t max_render_pixels = int64_t{1024} * 768;
  int max_concurrent_renders = 2;  // more get 503 (a render holds a device worker)
  absl::Duration render_timeout = absl::Seconds(20);
  int64_t max_points = 500000;     // per point cloud (7.5 MB of PLY)
  // Triangles per mesh, counted as marching cubes makes them (before the faces no view saw are
  // dropped): about 27 MB of PLY at most. A larger mesh is refused with 413: a browser would
  // not draw it smoothly, and `plenox export --mesh` writes it.
  int64_t max_mesh_triangles = 1'000'000;
  absl::Duration mesh_timeout = absl::Seconds(60);  // on the device, like a render's
  // Camera positions per track and keyframes per map in a trajectory answer.
  int max_track_points = 2048;
  int max_keyframes = 2048;
};

// The HTTP status for an error of a source or a check (404 NotFound, 400 InvalidArgument and
// OutOfRange, 401 Unauthenticated, 503 Unavailable/ResourceExhausted, 504 DeadlineExceeded,
// 500 otherwise).
int HttpStatusOf(const absl::Status& status);

class Viewer {
 public:
  // `source` must outlive the viewer, and the viewer the server it adds its routes to.
  Viewer(ViewerSource* source, ThreeJsFiles three, ViewerOptions options);

  void AddRoutes(HttpServer& server);

  // Answers one request under /viewer (the routes call this; tests may too).
  HttpResponse Handle(const HttpRequest& request);

 private:
  HttpResponse Api(const HttpRequest& request);
  HttpResponse Maps();
  HttpResponse Points(const std::string& map);
  HttpResponse Mesh(const HttpRequest& request, const std::string& map);
  HttpResponse MeshGlb(const HttpRequest& request, const std::string& map);
  HttpResponse Trajectory(const std::string& map);
  HttpResponse Render(const HttpRequest& request, const std::string& map);
  absl::Status CheckToken(const HttpRequest& request) const;

  ViewerSource* const source_;
  const ThreeJsFiles three_;
  const ViewerOptions options_;
  PointCloudCache points_;
  MeshCache meshes_;
  std::atomic<int> renders_{0};
};

}  // namespace plx::web

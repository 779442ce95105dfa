#include "web/viewer_routes.h"

#include <algorithm>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/formats/glb_mesh.h"
#include "core/geometry/axis_box.h"
#include "core/render/render_view.h"
#include "web/json_writer.h"
#include "web/viewer_assets.h"
#include "web/viewer_render.h"

namespace plx::web {
namespace {

constexpr char kJson[] = "application/json";
constexpr size_t kMaxMapNameBytes = 256;

// Answers of the API change with every poll: never cached. The page itself may be cached but
// is revalidated, so a new program's page replaces the old one.
const std::pair<std::string, std::string> kNoStore = {"Cache-Control", "no-store"};
const std::pair<std::string, std::string> kRevalidate = {"Cache-Control", "no-cache"};

HttpResponse JsonError(int status, absl::string_view message) {
  JsonWriter json;
  json.BeginObject().Key("error").String(message).EndObject();
  HttpResponse r{status, kJson, json.str(), {kNoStore}};
  if (status == 401) r.headers.push_back({"WWW-Authenticate", "Bearer"});
  if (status == 503) r.headers.push_back({"Retry-After", "1"});
  return r;
}

HttpResponse ErrorResponse(const absl::Status& status) {
  return JsonError(HttpStatusOf(status), status.message());
}

// Compares without stopping at the first difference, so the time taken does not tell an
// attacker how much of a guessed token was right.
bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  }
  return diff == 0;
}

void PoseJson(JsonWriter& json, const SE3& pose) {
  const Eigen::Vector3d& t = pose.translation();
  const Eigen::Quaterniond& q = pose.rotation();
  const double values[7] = {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
  json.Numbers(values, 7);
}

}  // namespace

int HttpStatusOf(const absl::Status& status) {
  switch (status.code()) {
    case absl::StatusCode::kOk: return 200;
    case absl::StatusCode::kNotFound: return 404;
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kOutOfRange: return 400;
    case absl::StatusCode::kUnauthenticated: return 401;
    case absl::StatusCode::kPermissionDenied: return 403;
    case absl::StatusCode::kUnavailable:
    case absl::StatusCode::kResourceExhausted:
    case absl::StatusCode::kCancelled: return 503;
    case absl::StatusCode::kDeadlineExceeded: return 504;
    default: return 500;
  }
}

Viewer::Viewer(ViewerSource* source, ThreeJsFiles three, ViewerOptions options)
    : source_(source),
      three_(std::move(three)),
      options_(std::move(options)),
      points_(options_.max_points),
      meshes_(options_.max_mesh_triangles, options_.mesh_timeout) {}

void Viewer::AddRoutes(HttpServer& server) {
  server.GetPrefix("/viewer", [this](const HttpRequest& r) { return Handle(r); });
}

absl::Status Viewer::CheckToken(const HttpRequest& request) const {
  if (options_.auth_token.empty()) return absl::OkStatus();
  if (!request.authorization.empty()) {
    if (ConstantTimeEquals(request.authorization, "Bearer " + options_.auth_token)) {
      return absl::OkStatus();
    }
    return absl::UnauthenticatedError("invalid bearer token");
  }
  if (const std::string* token = request.Param("token")) {
    if (ConstantTimeEquals(*token, options_.auth_token)) return absl::OkStatus();
    return absl::UnauthenticatedError("invalid token");
  }
  return absl::UnauthenticatedError(
      "missing credentials: send \"Authorization: Bearer <token>\" (the page: open "
      "/viewer/#token=<token>)");
}

HttpResponse Viewer::Handle(const HttpRequest& request) {
  const std::string& path = request.path;
  const std::map<std::string, std::string>& assets = EmbeddedAssets();
  auto asset = [&](const char* name, const char* type) {
    const auto it = assets.find(name);
    if (it == assets.end()) return JsonError(500, "the page was not built in");
    return HttpResponse{200, type, {}, {kRevalidate}, UnownedBody(it->second)};
  };
  if (path == "/viewer" || path == "/viewer/" || path == "/viewer/index.html") {
    return asset("index.html", "text/html; charset=utf-8");
  }
  if (path == "/viewer/viewer.js") return asset("viewer.js", "text/javascript; charset=utf-8");
  if (path == "/viewer/viewer.css") return asset("viewer.css", "text/css; charset=utf-8");
  // The viewer outlives the server that sends these (viewer_routes.h), so they are sent from
  // the viewer's one copy.
  if (path == "/viewer/three/three.min.js") {
    return HttpResponse{200, "text/javascript; charset=utf-8", {}, {kRevalidate},
                        UnownedBody(three_.three)};
  }
  if (path == "/viewer/three/OrbitControls.js") {
    return HttpResponse{200, "text/javascript; charset=utf-8", {}, {kRevalidate},
                        UnownedBody(three_.orbit_controls)};
  }
  if (path == "/viewer/three/GLTFLoader.js") {
    return HttpResponse{200, "text/javascript; charset=utf-8", {}, {kRevalidate},
                        UnownedBody(three_.gltf_loader)};
  }
  if (absl::StartsWith(path, "/viewer/api/")) return Api(request);
  return JsonError(404, absl::StrCat("no such page: ", path.substr(0, 128)));
}

HttpResponse Viewer::Api(const HttpRequest& request) {
  if (absl::Status s = CheckToken(request); !s.ok()) return ErrorResponse(s);
  const std::string endpoint = request.path.substr(sizeof("/viewer/api/") - 1);
  if (endpoint == "maps") return Maps();
  if (endpoint != "points" && endpoint != "mesh" && endpoint != "mesh.glb" &&
      endpoint != "trajectory" && endpoint != "render") {
    return JsonError(404, absl::StrCat("no such endpoint: ", request.path.substr(0, 128)));
  }
  const std::string* map = request.Param("map");
  if (map == nullptr || map->empty()) return JsonError(400, "map: missing");
  if (map->size() > kMaxMapNameBytes) return JsonError(400, "map: name too long");
  if (endpoint == "points") return Points(*map);
  if (endpoint == "mesh") return Mesh(request, *map);
  if (endpoint == "mesh.glb") return MeshGlb(request, *map);
  if (endpoint == "trajectory") return Trajectory(*map);
  return Render(request, *map);
}

HttpResponse Viewer::Maps() {
  JsonWriter json;
  json.BeginObject().Key("title").String(source_->Title());
  json.Key("auth").Bool(!options_.auth_token.empty());
  json.Key("max_render_side").Int(kMaxViewerRenderSide);
  json.Key("max_render_pixels").Int(options_.max_render_pixels);
  json.Key("max_mesh_triangles").Int(options_.max_mesh_triangles);
  json.Key("maps").BeginArray();
  for (const MapStatus& m : source_->ListMaps()) {
    json.BeginObject()
        .Key("name").String(m.name)
        .Key("voxel_size").Number(m.voxel_size)
        .Key("version").Int(static_cast<int64_t>(m.version))
        .Key("bricks").Int(m.bricks)
        .Key("memory_bytes").Int(m.memory_bytes)
        .Key("keyframes").Int(m.keyframes)
        .Key("mapping").Bool(m.mapping)
        .Key("source").String(m.source)
        .EndObject();
  }
  json.EndArray().EndObject();
  return HttpResponse{200, kJson, json.str(), {kNoStore}};
}

HttpResponse Viewer::Points(const std::string& map) {
  absl::StatusOr<ViewerMap> latest = source_->Latest(map);
  if (!latest.ok()) return ErrorResponse(latest.status());
  absl::StatusOr<std::shared_ptr<const PointCloud>> cloud = points_.Get(map, *latest);
  if (!cloud.ok()) return ErrorResponse(cloud.status());
  // Sent from the cache's copy (it stays alive while being sent, even when evicted).
  return HttpResponse{200,
                      "application/octet-stream",
                      {},
                      {kNoStore,
                       {"X-Map-Version", absl::StrCat(latest->version)},
                       {"X-Points", absl::StrCat((*cloud)->points)},
                       {"X-Surface-Points", absl::StrCat((*cloud)->surface_points)}},
                      std::shared_ptr<const std::string>(*cloud, &(*cloud)->ply)};
}

namespace {

// The level of detail a mesh.glb request asks for: `triangles`, absent or 0 for the full mesh.
absl::StatusOr<int64_t> ParseTriangleBudget(const HttpRequest& request, int64_t max_triangles) {
  const std::string* value = request.Param("triangles");
  if (value == nullptr || value->empty()) return 0;
  int64_t triangles = -1;
  // Digits only (no sign, space or exponent), and few enough that the value cannot overflow.
  const bool digits =
      value->size() <= 12 &&
      std::all_of(value->begin(), value->end(), [](char c) { return c >= '0' && c <= '9'; });
  if (!digits || !absl::SimpleAtoi(*value, &triangles) || triangles > max_triangles) {
    return absl::InvalidArgumentError(absl::StrCat(
        "triangles: expected a whole number from 0 to ", max_triangles,
        " (the viewer's mesh limit; 0 = the full mesh), got \"", value->substr(0, 32), "\""));
  }
  return triangles;
}

// The region a mesh or mesh.glb request asks for: `bbox` = "xmin,ymin,zmin,xmax,ymax,zmax"
// (metres, map coordinates; as `plenox export --bbox` takes it), absent for the whole map.
absl::StatusOr<std::optional<AxisBox>> ParseRegion(const HttpRequest& request) {
  const std::string* value = request.Param("bbox");
  if (value == nullptr) return std::nullopt;
  const std::vector<absl::string_view> parts = absl::StrSplit(*value, ',');
  AxisBox box;
  bool ok = parts.size() == 6 && value->size() <= 512;
  for (size_t i = 0; ok && i < parts.size(); ++i) {
    ok = absl::SimpleAtod(parts[i], i < 3 ? &box.min[i] : &box.max[i - 3]);
  }
  if (!ok) {
    return absl::InvalidArgumentError(absl::StrCat(
        "bbox: expected six numbers xmin,ymin,zmin,xmax,ymax,zmax (metres, map coordinates), "
        "got \"", value->substr(0, 64), "\""));
  }
  if (absl::Status s = CheckAxisBox(box, "bbox"); !s.ok()) return s;
  return box;
}

// A mesh (PLY or GLB) of `version` over the triangle cap: 413 with the reason.
HttpResponse MeshTooLarge(const std::string& why, uint64_t version) {
  HttpResponse r = JsonError(413, why);
  r.headers.push_back({"X-Map-Version", absl::StrCat(version)});
  return r;
}

}  // namespace

HttpResponse Viewer::Mesh(const HttpRequest& request, const std::string& map) {
  absl::StatusOr<std::optional<AxisBox>> region = ParseRegion(request);
  if (!region.ok()) return ErrorResponse(region.status());
  absl::StatusOr<ViewerMap> latest = source_->Latest(map);
  if (!latest.ok()) return ErrorResponse(latest.status());
  absl::StatusOr<std::shared_ptr<const ViewerMesh>> mesh =
      *region ? meshes_.GetRegion(*source_, map, *latest, **region)
              : meshes_.Get(*source_, map, *latest);
  if (!mesh.ok()) return ErrorResponse(mesh.status());
  if (!(*mesh)->too_large.empty()) return MeshTooLarge((*mesh)->too_large, latest->version);
  return HttpResponse{200,
                      "application/octet-stream",
                      {},
                      {kNoStore,
                       {"X-Map-Version", absl::StrCat(latest->version)},
                       {"X-Vertices", absl::StrCat((*mesh)->vertices)},
                       {"X-Faces", absl::StrCat((*mesh)->faces)}},
                      std::shared_ptr<const std::string>(*mesh, &(*mesh)->ply)};
}

HttpResponse Viewer::MeshGlb(const HttpRequest& request, const std::string& map) {
  absl::StatusOr<int64_t> triangles = ParseTriangleBudget(request, options_.max_mesh_triangles);
  if (!triangles.ok()) return ErrorResponse(triangles.status());
  absl::StatusOr<std::optional<AxisBox>> region = ParseRegion(request);
  if (!region.ok()) return ErrorResponse(region.status());
  absl::StatusOr<ViewerMap> latest = source_->Latest(map);
  if (!latest.ok()) return ErrorResponse(latest.status());
  absl::StatusOr<std::shared_ptr<const ViewerGlb>> glb =
      *region ? meshes_.GetRegionGlb(*source_, map, *latest, *triangles, **region)
              : meshes_.GetGlb(*source_, map, *latest, *triangles);
  if (!glb.ok()) return ErrorResponse(glb.status());
  if (!(*glb)->too_large.empty()) return MeshTooLarge((*glb)->too_large, latest->version);
  return HttpResponse{200,
                      kGlbMediaType,
                      {},
                      {kNoStore,
                       {"X-Map-Version", absl::StrCat(latest->version)},
                       {"X-Vertices", absl::StrCat((*glb)->vertices)},
                       {"X-Faces", absl::StrCat((*glb)->faces)},
                       {"X-Full-Faces", absl::StrCat((*glb)->full_faces)},
                       {"X-Lod-Error-M", absl::StrCat((*glb)->lod_error_m)}},
                      std::shared_ptr<const std::string>(*glb, &(*glb)->glb)};
}

HttpResponse Viewer::Trajectory(const std::string& map) {
  absl::StatusOr<ViewerTrajectories> t = source_->Trajectories(map);
  if (!t.ok()) return ErrorResponse(t.status());
  JsonWriter json;
  json.BeginObject()
      .Key("map").String(map)
      .Key("slam_running").Bool(t->slam_running)
      .Key("keyframes_integrated").Int(t->keyframes_integrated)
      .Key("map_version").Int(static_cast<int64_t>(t->map_version));
  json.Key("cameras").BeginArray();
  for (const CameraTrack& c : t->cameras) {
    json.BeginObject()
        .Key("id").Int(c.id)
        .Key("label").String(c.label)
        .Key("active").Bool(c.active)
        .Key("state").String(c.state)
        .Key("frames").Int(c.frames)
        .Key("timestamp").Number(c.timestamp)
        .Key("pose");
    PoseJson(json, c.pose);
    // Flat x,y,z triples, the newest positions when a source kept more than the bound.
    json.Key("path").BeginArray();
    const size_t n = c.path.size();
    const size_t keep = std::min(n, static_cast<size_t>(options_.max_track_points));
    for (size_t i = n - keep; i < n; ++i) {
      json.Number(c.path[i].x()).Number(c.path[i].y()).Number(c.path[i].z());
    }
    json.EndArray().EndObject();
  }
  json.EndArray();
  json.Key("keyframes").BeginArray();
  const size_t n = t->keyframes.size();
  const size_t keep = std::min(n, static_cast<size_t>(options_.max_keyframes));
  for (size_t i = n - keep; i < n; ++i) PoseJson(json, t->keyframes[i]);
  json.EndArray();
  // Loop edges as [from, to] indices into the keyframes sent (both ends among them).
  json.Key("loops").BeginArray();
  const int first = static_cast<int>(n - keep);
  for (const auto& [from, to] : t->loops) {
    if (from < first || to < first || from >= static_cast<int>(n) || to >= static_cast<int>(n)) {
      continue;
    }
    json.BeginArray().Int(from - first).Int(to - first).EndArray();
  }
  json.EndArray().EndObject();
  return HttpResponse{200, kJson, json.str(), {kNoStore}};
}

HttpResponse Viewer::Render(const HttpRequest& request, const std::string& map) {
  absl::StatusOr<ViewerRenderRequest> parsed =
      ParseViewerRenderRequest(request, options_.max_render_pixels);
  if (!parsed.ok()) return ErrorResponse(parsed.status());
  absl::StatusOr<ViewerMap> latest = source_->Latest(map);
  if (!latest.ok()) return ErrorResponse(latest.status());
  // A slot per render: the device worker's queue stays short whatever the pages ask for.
  if (renders_.fetch_add(1) >= options_.max_concurrent_renders) {
    renders_.fetch_sub(1);
    return JsonError(503, absl::StrCat("busy: ", options_.max_concurrent_renders,
                                       " renders are running; retry"));
  }
  absl::StatusOr<RenderedView> view = absl::UnknownError("not rendered");
  const absl::Status ran = source_->RunOnDevice(
      [&](Backend& backend, const std::function<bool()>& cancelled) {
        RenderViewOptions options;
        options.cancelled = cancelled;  // checked between row tiles
        view = RenderView(backend, *latest->map, parsed->world_T_camera, parsed->intrinsics,
                          options);
        return view.status();
      },
      options_.render_timeout);
  renders_.fetch_sub(1);
  if (!ran.ok()) return ErrorResponse(ran);
  absl::StatusOr<ViewerImagePng> png = EncodeViewerImage(*view, parsed->image);
  if (!png.ok()) return ErrorResponse(png.status());
  HttpResponse r{200, "image/png", std::move(png->png),
                 {kNoStore, {"X-Map-Version", absl::StrCat(latest->version)}}};
  if (parsed->image == ViewerImage::kDepth) {
    r.headers.push_back({"X-Depth-Range", absl::StrCat(png->near_m, ",", png->far_m)});
  }
  return r;
}

}  // namespace plx::web

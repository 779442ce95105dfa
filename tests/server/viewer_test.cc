// The web viewer on plenoxd's HTTP port (--viewer): the page and three.js, the map list, point
// clouds, live SLAM trajectories and renders, authentication, and bad requests answered with
// 4xx instead of work or a crash. Also the pieces on their own: the point cloud thinning and the
// mesh endpoints' triangle cap and caches, the glTF levels of detail among them (the trajectory
// record's bounds: trajectory_record_test).
#include <cmath>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "app/make_backend.h"
#include "core/formats/map_file.h"
#include "core/io/image_io.h"
#include "core/formats/glb_mesh.h"
#include "tests/glb_reader.h"
#include "tests/ply_mesh_reader.h"
#include "tests/server/viewer_fixture.h"
#include "web/point_cloud_cache.h"
#include "web/viewer_mesh.h"
#include "web/viewer_routes.h"

namespace plx::server::testing {
namespace {

int CountOccurrences(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// The number after `"key":` in a JSON text (the first occurrence), or -1.
double JsonNumber(const std::string& json, const std::string& key) {
  const std::string pattern = absl::StrCat("\"", key, "\":");
  const size_t at = json.find(pattern);
  if (at == std::string::npos) return -1;
  return std::atof(json.c_str() + at + pattern.size());
}

// The vertex count of a PLY header, or -1.
int64_t PlyVertices(const std::string& ply) {
  const std::string pattern = "element vertex ";
  const size_t at = ply.find(pattern);
  return at == std::string::npos ? -1 : std::atoll(ply.c_str() + at + pattern.size());
}

TEST(ViewerTest, ServesThePageTheMapsPointsAndRenders) {
  PLX_SKIP_WITHOUT_THREE_JS();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_viewer"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  ASSERT_GT(port, 0);

  for (const char* page : {"/viewer/", "/viewer"}) {
    const HttpAnswer html = HttpGetAnswer(port, page);
    EXPECT_EQ(html.status, 200) << page;
    EXPECT_NE(html.headers.find("content-type: text/html"), std::string::npos);
    EXPECT_NE(html.body.find("/viewer/three/three.min.js"), std::string::npos);
  }
  for (const char* script : {"/viewer/viewer.js", "/viewer/three/three.min.js",
                             "/viewer/three/OrbitControls.js"}) {
    const HttpAnswer js = HttpGetAnswer(port, script);
    EXPECT_EQ(js.status, 200) << script;
    EXPECT_NE(js.headers.find("content-type: text/javascript"), std::string::npos) << script;
    EXPECT_GT(js.body.size(), 1000u) << script;
  }
  EXPECT_NE(HttpGetAnswer(port, "/viewer/three/OrbitControls.js").body.find("OrbitControls"),
            std::string::npos);
  // /metrics is still served beside it.
  EXPECT_EQ(HttpGetAnswer(port, "/metrics").status, 200);

  const HttpAnswer maps = HttpGetAnswer(port, "/viewer/api/maps");
  ASSERT_EQ(maps.status, 200) << maps.body;
  EXPECT_NE(maps.headers.find("content-type: application/json"), std::string::npos);
  EXPECT_NE(maps.body.find("\"name\":\"room\""), std::string::npos) << maps.body;
  EXPECT_NE(maps.body.find("\"title\":\"plenoxd "), std::string::npos) << maps.body;

  const HttpAnswer points = HttpGetAnswer(port, "/viewer/api/points?map=room");
  ASSERT_EQ(points.status, 200) << points.body.substr(0, 200);
  ASSERT_EQ(points.body.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  const int64_t n = PlyVertices(points.body);
  EXPECT_GT(n, 1000);
  EXPECT_NE(points.headers.find(absl::StrCat("x-points: ", n)), std::string::npos);
  const size_t body_at = points.body.find("end_header\n") + 11;
  EXPECT_EQ(points.body.size() - body_at, static_cast<size_t>(n) * 15);
  // Asked again: the same cloud (built once per version).
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points?map=room").body, points.body);

  // The mesh: a PLY with normals, colours and triangles over the room's surfaces.
  const HttpAnswer mesh = HttpGetAnswer(port, "/viewer/api/mesh?map=room");
  ASSERT_EQ(mesh.status, 200) << mesh.body.substr(0, 200);
  EXPECT_NE(mesh.headers.find("content-type: application/octet-stream"), std::string::npos);
  absl::StatusOr<plx::testing::PlyMeshFile> read = plx::testing::ReadPlyMesh(mesh.body);
  ASSERT_TRUE(read.ok()) << read.status();
  const TriangleMesh& m = read->mesh;
  EXPECT_GT(m.num_triangles(), 1000);
  EXPECT_NE(mesh.headers.find(absl::StrCat("x-faces: ", m.num_triangles())), std::string::npos)
      << mesh.headers;
  EXPECT_NE(mesh.headers.find("x-map-version: "), std::string::npos);
  const int64_t vertices = static_cast<int64_t>(m.positions.size() / 3);
  int64_t unit_normals = 0, coloured = 0;
  for (int64_t v = 0; v < vertices; ++v) {
    const float* n3 = &m.normals[3 * v];
    unit_normals += std::abs(std::sqrt(n3[0] * n3[0] + n3[1] * n3[1] + n3[2] * n3[2]) - 1) < 1e-3;
    coloured += m.colors[3 * v] + m.colors[3 * v + 1] + m.colors[3 * v + 2] > 0;
  }
  EXPECT_GT(unit_normals, vertices * 99 / 100);
  EXPECT_GT(coloured, vertices * 9 / 10);
  for (int32_t index : m.triangles) {
    ASSERT_GE(index, 0);
    ASSERT_LT(index, vertices);
  }
  // Asked again: the same mesh (built once per version).
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh?map=room").body, mesh.body);

  // The same mesh as binary glTF: in full, and at a level of detail.
  const HttpAnswer glb = HttpGetAnswer(port, "/viewer/api/mesh.glb?map=room");
  ASSERT_EQ(glb.status, 200) << glb.body.substr(0, 200);
  EXPECT_NE(glb.headers.find("content-type: model/gltf-binary"), std::string::npos);
  absl::StatusOr<plx::testing::GlbFile> full_glb = plx::testing::ReadGlb(glb.body);
  ASSERT_TRUE(full_glb.ok()) << full_glb.status();
  EXPECT_EQ(full_glb->mesh.positions, m.positions);
  EXPECT_EQ(full_glb->mesh.triangles, m.triangles);
  EXPECT_NE(glb.headers.find(absl::StrCat("x-full-faces: ", m.num_triangles())),
            std::string::npos)
      << glb.headers;
  const int64_t budget = m.num_triangles() / 10;
  const HttpAnswer lod =
      HttpGetAnswer(port, absl::StrCat("/viewer/api/mesh.glb?map=room&triangles=", budget));
  ASSERT_EQ(lod.status, 200) << lod.body.substr(0, 200);
  absl::StatusOr<plx::testing::GlbFile> lod_glb = plx::testing::ReadGlb(lod.body);
  ASSERT_TRUE(lod_glb.ok()) << lod_glb.status();
  EXPECT_LE(lod_glb->mesh.num_triangles(), budget);
  EXPECT_GT(lod_glb->mesh.num_triangles(), budget / 2);
  EXPECT_NE(lod.headers.find(absl::StrCat("x-faces: ", lod_glb->mesh.num_triangles())),
            std::string::npos)
      << lod.headers;
  EXPECT_NE(lod.headers.find("x-lod-error-m: "), std::string::npos);
  EXPECT_EQ(HttpGetAnswer(port, absl::StrCat("/viewer/api/mesh.glb?map=room&triangles=", budget))
                .body,
            lod.body);

  const HttpAnswer color = HttpGetAnswer(port, RenderQuery("room", 5, 160, 120, "color"));
  ASSERT_EQ(color.status, 200) << color.body;
  EXPECT_NE(color.headers.find("content-type: image/png"), std::string::npos);
  absl::StatusOr<cv::Mat> decoded = DecodeColorBuffer(color.body, "render");
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const ColorImage image = ColorImageFromMat(*decoded);
  EXPECT_EQ(image.width, 160);
  EXPECT_EQ(image.height, 120);
  int lit = 0;
  for (int64_t i = 0; i < image.num_pixels(); ++i) {
    lit += image.data[3 * i] + image.data[3 * i + 1] + image.data[3 * i + 2] > 0.1f;
  }
  EXPECT_GT(lit, image.num_pixels() * 9 / 10) << "the room fills the view from its own path";
  const HttpAnswer depth = HttpGetAnswer(port, RenderQuery("room", 5, 160, 120, "depth"));
  ASSERT_EQ(depth.status, 200) << depth.body;
  EXPECT_NE(depth.headers.find("x-depth-range: "), std::string::npos);
  EXPECT_NE(depth.body, color.body);

  // A map without SLAM has no cameras.
  const HttpAnswer trajectory = HttpGetAnswer(port, "/viewer/api/trajectory?map=room");
  ASSERT_EQ(trajectory.status, 200) << trajectory.body;
  EXPECT_NE(trajectory.body.find("\"cameras\":[]"), std::string::npos) << trajectory.body;
}

TEST(ViewerTest, BadRequestsGet4xxAndTheDaemonGoesOn) {
  PLX_SKIP_WITHOUT_THREE_JS();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_viewer_bad"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  const std::string ok_pose = "0%2C0%2C0%2C0%2C0%2C0%2C1";
  auto render = [&](const std::string& params) {
    return HttpGetAnswer(port, "/viewer/api/render?map=room&" + params).status;
  };
  const std::string size = "&width=64&height=48&fov=50";
  // Unknown maps and paths.
  for (const std::string& path :
       {std::string("/viewer/api/points?map=nope"), std::string("/viewer/api/trajectory?map=nope"),
        std::string("/viewer/api/mesh?map=nope"),
        absl::StrCat("/viewer/api/render?map=nope&pose=", ok_pose, size),
        std::string("/viewer/api/nothing"), std::string("/viewer/api/"),
        std::string("/viewer/../metrics/x"), std::string("/viewer/three/../../etc/passwd"),
        std::string("/viewer/three/three.js"), std::string("/viewerx"),
        std::string("/viewer/%2e%2e/%2e%2e/etc/passwd"), std::string("/")}) {
    const HttpAnswer a = HttpGetAnswer(port, path);
    EXPECT_EQ(a.status, 404) << path << ": " << a.body;
  }
  // A path that decodes to a NUL is not a path at all.
  EXPECT_EQ(HttpGetAnswer(port, "/%00").status, 400);
  // Missing or malformed parameters, sizes and ranges.
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points").status, 400);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points?map=").status, 400);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points?map=" + std::string(300, 'x')).status, 400);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh").status, 400);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh.glb").status, 400);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh.glb?map=nope").status, 404);
  for (const char* triangles : {"abc", "-1", "1e3", "%2B5", "12.5", "1000001", "99999999999999",
                                "5%20"}) {
    const HttpAnswer a =
        HttpGetAnswer(port, absl::StrCat("/viewer/api/mesh.glb?map=room&triangles=", triangles));
    EXPECT_EQ(a.status, 400) << triangles << ": " << a.body;
    EXPECT_NE(a.body.find("triangles: expected a whole number from 0 to 1000000"),
              std::string::npos)
        << a.body;
  }
  EXPECT_EQ(render(size), 400);                                             // no pose
  EXPECT_EQ(render("pose=1%2C2%2C3" + size), 400);                          // 3 numbers
  EXPECT_EQ(render("pose=0%2C0%2C0%2C0%2C0%2C0%2C0" + size), 400);          // zero quaternion
  EXPECT_EQ(render("pose=nan%2C0%2C0%2C0%2C0%2C0%2C1" + size), 400);
  EXPECT_EQ(render("pose=1e300%2C0%2C0%2C0%2C0%2C0%2C1" + size), 400);      // outside the world
  EXPECT_EQ(render("pose=" + ok_pose + "&width=64&height=48"), 400);        // no fov
  EXPECT_EQ(render("pose=" + ok_pose + "&width=64&height=48&fov=0"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=64&height=48&fov=180"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=0&height=48&fov=50"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=-5&height=48&fov=50"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=100000&height=100000&fov=50"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=99999999999999999999&height=4&fov=50"), 400);
  EXPECT_EQ(render("pose=" + ok_pose + "&width=1024&height=1024&fov=50"), 400);  // > pixels
  EXPECT_EQ(render("pose=" + ok_pose + size + "&image=normals"), 400);
  // A request line over the server's 8 KiB bound is refused (414) before any handler.
  const HttpAnswer huge = HttpGetAnswer(port, "/viewer/api/points?map=" + std::string(20000, 'x'));
  EXPECT_GE(huge.status, 400);
  EXPECT_LT(huge.status, 500);
  // Still serving.
  EXPECT_EQ(render("pose=" + ok_pose + size), 200);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/maps").status, 200);
  EXPECT_EQ(HealthCheck(*(*started)->health), kServing);
}

TEST(ViewerTest, ApiNeedsTheTokenWhenAuthIsOn) {
  PLX_SKIP_WITHOUT_THREE_JS();
  DaemonOptions o = ViewerDaemonOptions("plx_srv_viewer_auth");
  o.auth_token = "s3cret-token";
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  // The page carries no map data: served to anyone, and it asks for the token.
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/").status, 200);
  const HttpAnswer none = HttpGetAnswer(port, "/viewer/api/maps");
  EXPECT_EQ(none.status, 401);
  EXPECT_NE(none.headers.find("www-authenticate: bearer"), std::string::npos);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/maps", "Authorization: Bearer wrong\r\n").status,
            401);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points?map=room&token=wrong").status, 401);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/points?map=nope").status, 401)
      << "no answer about which maps exist without the token";
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh?map=room").status, 401);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/mesh?map=room&token=wrong").status, 401);
  const HttpAnswer mesh =
      HttpGetAnswer(port, "/viewer/api/mesh?map=room", "Authorization: Bearer s3cret-token\r\n");
  EXPECT_EQ(mesh.status, 200) << mesh.body.substr(0, 200);
  EXPECT_TRUE(plx::testing::ReadPlyMesh(mesh.body).ok());
  const HttpAnswer header =
      HttpGetAnswer(port, "/viewer/api/maps", "Authorization: Bearer s3cret-token\r\n");
  EXPECT_EQ(header.status, 200);
  EXPECT_NE(header.body.find("\"auth\":true"), std::string::npos);
  EXPECT_EQ(HttpGetAnswer(port, "/viewer/api/maps?token=s3cret-token").status, 200);
}

TEST(ViewerTest, StartChecksTheViewersNeeds) {
  DaemonOptions no_port = ViewerDaemonOptions("plx_srv_viewer_noport");
  no_port.metrics_port = -1;
  absl::StatusOr<std::unique_ptr<Daemon>> d = Daemon::Start(no_port);
  EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument) << d.status();
  EXPECT_NE(d.status().message().find("--metrics-port"), std::string::npos) << d.status();

  DaemonOptions no_three = ViewerDaemonOptions("plx_srv_viewer_nothree");
  no_three.viewer_three_dir = plx::testing::MakeTempDir("plx_srv_no_three");
  d = Daemon::Start(no_three);
  EXPECT_EQ(d.status().code(), absl::StatusCode::kNotFound) << d.status();
  EXPECT_NE(d.status().message().find("libjs-three"), std::string::npos) << d.status();

  // Off unless asked for: no /viewer/ on the metrics port.
  DaemonOptions off = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_viewer_off"));
  off.metrics_port = 0;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(off);
  ASSERT_TRUE(started.ok()) << started.status();
  EXPECT_EQ(HttpGetAnswer((*started)->daemon->metrics_port(), "/viewer/").status, 404);
}

// A running Slam stream shows up: its camera (pose, path), its keyframes, the live map.
TEST(ViewerTest, TrajectoryFollowsARunningSlamStream) {
  PLX_SKIP_WITHOUT_THREE_JS();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartTestDaemon(ViewerDaemonOptions("plx_srv_viewer_slam"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  OpenSlamStream stream(*(*started)->stub, "live", ViewerSlamOptions());
  ASSERT_TRUE(stream.Advance(6));
  // The live map has content once keyframe 0 is integrated (the stream's frames do not wait
  // for it: the odometry carries the first ones).
  int points = 0;
  HttpAnswer t;
  for (int attempt = 0; attempt < 300; ++attempt) {
    points = PlyVertices(HttpGetAnswer(port, "/viewer/api/points?map=live").body);
    t = HttpGetAnswer(port, "/viewer/api/trajectory?map=live");
    if (points > 100 && t.body.find("\"keyframes\":[[") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_GT(points, 100);
  ASSERT_EQ(t.status, 200) << t.body;
  EXPECT_NE(t.body.find("\"slam_running\":true"), std::string::npos) << t.body;
  EXPECT_NE(t.body.find("\"active\":true"), std::string::npos) << t.body;
  EXPECT_EQ(JsonNumber(t.body, "frames"), 6) << t.body;
  EXPECT_NE(t.body.find("\"keyframes\":[["), std::string::npos) << t.body;
  EXPECT_NE(t.body.find("\"loops\":[]"), std::string::npos) << t.body;  // six frames: no loop
  // The camera's pose is frame 5's, near the truth.
  const size_t pose_at = t.body.find("\"pose\":[");
  ASSERT_NE(pose_at, std::string::npos);
  const Eigen::Vector3d truth = GroundTruth(5).translation();
  double x = 0, y = 0, z = 0;
  ASSERT_EQ(std::sscanf(t.body.c_str() + pose_at + 8, "%lf,%lf,%lf", &x, &y, &z), 3);
  EXPECT_LT((Eigen::Vector3d(x, y, z) - truth).norm(), 0.05) << t.body.substr(pose_at, 120);

  ASSERT_TRUE(stream.Advance(4));
  t = HttpGetAnswer(port, "/viewer/api/trajectory?map=live");
  EXPECT_EQ(JsonNumber(t.body, "frames"), 10) << t.body;
  const grpc::Status closed = stream.Close();
  ASSERT_TRUE(closed.ok()) << Describe(closed);
  // After the stream: the camera is kept, marked ended.
  t = HttpGetAnswer(port, "/viewer/api/trajectory?map=live");
  EXPECT_NE(t.body.find("\"active\":false"), std::string::npos) << t.body;
  EXPECT_EQ(CountOccurrences(t.body, "\"id\":"), 1) << t.body;
}

TEST(PointCloudThinningTest, KeepsEveryKthPointAndRewritesTheCount) {
  std::string body;
  const int n = 1000;
  for (int i = 0; i < n; ++i) {
    const float xyz[3] = {static_cast<float>(i), 0.0f, 0.0f};
    body.append(reinterpret_cast<const char*>(xyz), 12);
    body.append("\x01\x02\x03", 3);
  }
  const std::string ply = absl::StrCat(
      "ply\nformat binary_little_endian 1.0\ncomment t\nelement vertex ", n,
      "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n"
      "property uchar green\nproperty uchar blue\nend_header\n", body);
  absl::StatusOr<web::PointCloud> thin = web::ThinPointCloudPly(ply, 300);
  ASSERT_TRUE(thin.ok()) << thin.status();
  EXPECT_EQ(thin->surface_points, n);
  EXPECT_EQ(thin->points, 250);  // every 4th
  EXPECT_EQ(PlyVertices(thin->ply), 250);
  const size_t body_at = thin->ply.find("end_header\n") + 11;
  ASSERT_EQ(thin->ply.size() - body_at, 250u * 15);
  float x = 0;
  std::memcpy(&x, thin->ply.data() + body_at + 15 * 249, 4);
  EXPECT_EQ(x, 996.0f);
  absl::StatusOr<web::PointCloud> all = web::ThinPointCloudPly(ply, 5000);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->ply, ply);
  EXPECT_FALSE(web::ThinPointCloudPly(ply.substr(0, ply.size() - 1), 300).ok());
  EXPECT_FALSE(web::ThinPointCloudPly("not a ply", 300).ok());
}

// One map file on this process's CPU backend, counting the device calls: what the mesh cache
// saves is visible.
class CountingSource final : public web::ViewerSource {
 public:
  CountingSource(std::shared_ptr<const PlenoxelMap> map, std::unique_ptr<Backend> backend)
      : map_(std::move(map)), backend_(std::move(backend)) {}
  std::string Title() const override { return "test"; }
  std::vector<MapStatus> ListMaps() const override { return {}; }
  absl::StatusOr<web::ViewerMap> Latest(const std::string& name) const override {
    if (name != "room") return absl::NotFoundError("no map " + name);
    return web::ViewerMap{map_, version};
  }
  absl::StatusOr<web::ViewerTrajectories> Trajectories(const std::string&) const override {
    return web::ViewerTrajectories{};
  }
  absl::Status RunOnDevice(const DeviceWork& work, absl::Duration) override {
    ++device_calls;
    return work(*backend_, [] { return false; });
  }
  uint64_t version = 1;
  int device_calls = 0;

 private:
  std::shared_ptr<const PlenoxelMap> map_;
  std::unique_ptr<Backend> backend_;
};

web::HttpRequest MeshRequest(const std::string& map) {
  web::HttpRequest r;
  r.path = "/viewer/api/mesh";
  r.params["map"] = map;
  return r;
}

TEST(ViewerMeshTest, OverTheTriangleCapIs413AndEachVersionIsBuiltOnce) {
  const std::string& file = CachedRoomMapFile();
  ASSERT_FALSE(file.empty());
  absl::StatusOr<std::unique_ptr<PlenoxelMap>> map = LoadMap(file);
  ASSERT_TRUE(map.ok()) << map.status();
  absl::StatusOr<std::unique_ptr<Backend>> backend = MakeBackend(BackendKind::kCpu, 0, 2);
  ASSERT_TRUE(backend.ok()) << backend.status();
  CountingSource source(std::shared_ptr<const PlenoxelMap>(std::move(*map)),
                        std::move(*backend));

  // Big enough: the mesh, once per version.
  web::Viewer roomy(&source, web::ThreeJsFiles{}, web::ViewerOptions{});
  web::HttpResponse ok = roomy.Handle(MeshRequest("room"));
  ASSERT_EQ(ok.status, 200) << ok.Body().substr(0, 200);
  absl::StatusOr<plx::testing::PlyMeshFile> read = plx::testing::ReadPlyMesh(ok.Body());
  ASSERT_TRUE(read.ok()) << read.status();
  const int64_t triangles = read->mesh.num_triangles();
  ASSERT_GT(triangles, 100);
  EXPECT_EQ(source.device_calls, 1);
  EXPECT_EQ(roomy.Handle(MeshRequest("room")).Body(), ok.Body());
  EXPECT_EQ(source.device_calls, 1) << "the same version is served from the cache";
  source.version = 2;
  EXPECT_EQ(roomy.Handle(MeshRequest("room")).status, 200);
  EXPECT_EQ(source.device_calls, 2) << "a new version is built again";
  EXPECT_EQ(roomy.Handle(MeshRequest("nope")).status, 404);
  EXPECT_EQ(source.device_calls, 2);

  // One triangle under the mesh's count (the cap bounds the triangles marching cubes makes,
  // which are at least those served): 413 with the reason, remembered for the version.
  web::ViewerOptions tight;
  tight.max_mesh_triangles = triangles - 1;
  web::Viewer capped(&source, web::ThreeJsFiles{}, tight);
  const web::HttpResponse refused = capped.Handle(MeshRequest("room"));
  EXPECT_EQ(refused.status, 413) << refused.Body();
  EXPECT_EQ(refused.content_type, "application/json");
  EXPECT_NE(refused.Body().find(absl::StrCat("more than ", triangles - 1, " triangles")),
            std::string::npos)
      << refused.Body();
  EXPECT_EQ(source.device_calls, 3);
  EXPECT_EQ(capped.Handle(MeshRequest("room")).status, 413);
  EXPECT_EQ(source.device_calls, 3) << "a refused version is not built again";
}

web::HttpRequest GlbRequest(const std::string& map, int64_t triangles) {
  web::HttpRequest r;
  r.path = "/viewer/api/mesh.glb";
  r.params["map"] = map;
  r.params["triangles"] = absl::StrCat(triangles);
  return r;
}

// Levels of detail come from the version's cached mesh (no new device work), each budget is
// built once, budgets at or above the mesh's size are the full mesh, and a mesh over the cap is
// 413 as GLB too.
TEST(ViewerMeshTest, LevelsOfDetailAreBuiltFromTheCachedMesh) {
  absl::StatusOr<std::unique_ptr<PlenoxelMap>> map = LoadMap(CachedRoomMapFile());
  ASSERT_TRUE(map.ok()) << map.status();
  absl::StatusOr<std::unique_ptr<Backend>> backend = MakeBackend(BackendKind::kCpu, 0, 2);
  ASSERT_TRUE(backend.ok()) << backend.status();
  CountingSource source(std::shared_ptr<const PlenoxelMap>(std::move(*map)),
                        std::move(*backend));
  web::Viewer viewer(&source, web::ThreeJsFiles{}, web::ViewerOptions{});
  const web::HttpResponse full = viewer.Handle(GlbRequest("room", 0));
  ASSERT_EQ(full.status, 200) << full.Body().substr(0, 200);
  EXPECT_EQ(full.content_type, "model/gltf-binary");
  const absl::StatusOr<GlbMeshInfo> full_info = ReadGlbMeshInfo(full.Body());
  ASSERT_TRUE(full_info.ok()) << full_info.status();
  EXPECT_EQ(source.device_calls, 1);
  EXPECT_EQ(viewer.Handle(MeshRequest("room")).status, 200);
  EXPECT_EQ(source.device_calls, 1) << "the PLY and the GLB share the version's mesh";

  const int64_t budget = full_info->triangles / 5;
  const web::HttpResponse lod = viewer.Handle(GlbRequest("room", budget));
  ASSERT_EQ(lod.status, 200);
  const absl::StatusOr<GlbMeshInfo> lod_info = ReadGlbMeshInfo(lod.Body());
  ASSERT_TRUE(lod_info.ok()) << lod_info.status();
  EXPECT_LE(lod_info->triangles, budget);
  EXPECT_EQ(lod_info->full_triangles, full_info->triangles);
  EXPECT_EQ(source.device_calls, 1);
  // Served from the cache: the very same bytes object.
  EXPECT_EQ(viewer.Handle(GlbRequest("room", budget)).shared_body.get(), lod.shared_body.get());
  // A budget at or above the mesh is the full mesh, the same entry.
  EXPECT_EQ(viewer.Handle(GlbRequest("room", full_info->triangles)).shared_body.get(),
            full.shared_body.get());

  web::ViewerOptions tight;
  tight.max_mesh_triangles = 10;
  web::Viewer capped(&source, web::ThreeJsFiles{}, tight);
  EXPECT_EQ(capped.Handle(GlbRequest("room", 5)).status, 413);
  EXPECT_EQ(capped.Handle(GlbRequest("room", 11)).status, 400) << "over the viewer's limit";
}

// mesh.glb?bbox= (and mesh?bbox=, the PLY): the mesh of that box alone, built on the device
// for it (a map whose whole mesh is over the cap may still have a room under it), recorded in
// the file, cached per box and budget; a bbox that is not six finite numbers with min < max is
// 400.
TEST(ViewerMeshTest, ABoxOfTheMapIsBuiltForItselfAndCached) {
  absl::StatusOr<std::unique_ptr<PlenoxelMap>> map = LoadMap(CachedRoomMapFile());
  ASSERT_TRUE(map.ok()) << map.status();
  absl::StatusOr<std::unique_ptr<Backend>> backend = MakeBackend(BackendKind::kCpu, 0, 2);
  ASSERT_TRUE(backend.ok()) << backend.status();
  CountingSource source(std::shared_ptr<const PlenoxelMap>(std::move(*map)),
                        std::move(*backend));
  web::Viewer viewer(&source, web::ThreeJsFiles{}, web::ViewerOptions{});
  const web::HttpResponse full = viewer.Handle(GlbRequest("room", 0));
  ASSERT_EQ(full.status, 200) << full.Body().substr(0, 200);
  const absl::StatusOr<plx::testing::GlbFile> whole = plx::testing::ReadGlb(full.Body());
  ASSERT_TRUE(whole.ok()) << whole.status();
  const double middle = 0.5 * (whole->position_min[0] + whole->position_max[0]);
  web::HttpRequest half = GlbRequest("room", 0);
  half.params["bbox"] = absl::StrFormat("-100,-100,-100,%.17g,100,100", middle);
  const web::HttpResponse answer = viewer.Handle(half);
  ASSERT_EQ(answer.status, 200) << answer.Body().substr(0, 200);
  EXPECT_EQ(source.device_calls, 2) << "the box is meshed on the device for itself";
  const absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(answer.Body());
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_GT(info->triangles, 0);
  EXPECT_LT(info->triangles, whole->mesh.num_triangles());
  ASSERT_TRUE(info->region.has_value());
  EXPECT_EQ(info->region->max[0], middle);
  EXPECT_EQ(viewer.Handle(half).shared_body.get(), answer.shared_body.get()) << "cached";
  EXPECT_EQ(source.device_calls, 2);
  // A level of detail of the box: another entry, from another build.
  half.params["triangles"] = absl::StrCat(info->triangles / 4);
  const web::HttpResponse lod = viewer.Handle(half);
  ASSERT_EQ(lod.status, 200);
  const absl::StatusOr<GlbMeshInfo> lod_info = ReadGlbMeshInfo(lod.Body());
  ASSERT_TRUE(lod_info.ok()) << lod_info.status();
  EXPECT_LE(lod_info->triangles, info->triangles / 4);
  EXPECT_EQ(lod_info->full_triangles, info->triangles);

  // The PLY mesh of the same box: the same triangles as the box's full GLB, its own build,
  // cached per box.
  web::HttpRequest ply_half = MeshRequest("room");
  ply_half.params["bbox"] = half.params["bbox"];
  const int device_calls = source.device_calls;
  const web::HttpResponse ply = viewer.Handle(ply_half);
  ASSERT_EQ(ply.status, 200) << ply.Body().substr(0, 200);
  const absl::StatusOr<plx::testing::PlyMeshFile> ply_mesh =
      plx::testing::ReadPlyMesh(ply.Body());
  ASSERT_TRUE(ply_mesh.ok()) << ply_mesh.status();
  EXPECT_EQ(ply_mesh->mesh.num_triangles(), info->triangles);
  EXPECT_EQ(source.device_calls, device_calls + 1);
  EXPECT_EQ(viewer.Handle(ply_half).shared_body.get(), ply.shared_body.get()) << "cached";
  EXPECT_EQ(source.device_calls, device_calls + 1);
  ply_half.params["bbox"] = "0,0,0,1,-1,1";
  EXPECT_EQ(viewer.Handle(ply_half).status, 400);

  // Under the whole map's cap, a box passes where the map is refused (the cap counts the
  // triangles marching cubes makes, before the unseen ones go: one under the map's served mesh).
  web::ViewerOptions tight;
  tight.max_mesh_triangles = whole->mesh.num_triangles() - 1;
  web::Viewer capped(&source, web::ThreeJsFiles{}, tight);
  EXPECT_EQ(capped.Handle(GlbRequest("room", 0)).status, 413);
  half.params["triangles"] = "0";
  EXPECT_EQ(capped.Handle(half).status, 200);

  for (const char* bad : {"1,2,3", "0,0,0,1,1,x", "0,0,0,1,-1,1", "0,0,0,nan,1,1", ""}) {
    web::HttpRequest r = GlbRequest("room", 0);
    r.params["bbox"] = bad;
    const web::HttpResponse refused = viewer.Handle(r);
    EXPECT_EQ(refused.status, 400) << bad;
    EXPECT_NE(refused.Body().find("bbox"), std::string::npos) << refused.Body();
  }
}

TEST(MapVersionCacheTest, VariantsOfAVersionAreKeptApartAndDroppedWithIt) {
  web::MapVersionCache<int> cache(4);
  int builds = 0;
  auto build = [&](int value) {
    return [&builds, value]() -> absl::StatusOr<int> {
      ++builds;
      return value;
    };
  };
  EXPECT_EQ(**cache.Get("a", 100, 1, build(1)), 1);
  EXPECT_EQ(**cache.Get("a", 200, 1, build(2)), 2);
  EXPECT_EQ(**cache.Get("a", 100, 1, build(9)), 1);
  EXPECT_EQ(builds, 2);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(**cache.Get("a", 100, 2, build(3)), 3);  // a new version drops both variants
  EXPECT_EQ(cache.size(), 1u);
}

TEST(MapVersionCacheTest, KeepsTheNewestEntriesAndDropsOldVersionsAndFailures) {
  web::MapVersionCache<int> cache(2);
  int builds = 0;
  auto build = [&](int value) {
    return [&builds, value]() -> absl::StatusOr<int> {
      ++builds;
      return value;
    };
  };
  EXPECT_EQ(**cache.Get("a", 1, build(10)), 10);
  EXPECT_EQ(**cache.Get("a", 1, build(99)), 10);
  EXPECT_EQ(builds, 1);
  EXPECT_EQ(**cache.Get("a", 2, build(20)), 20);  // replaces a@1
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(**cache.Get("b", 1, build(30)), 30);
  EXPECT_EQ(**cache.Get("c", 1, build(40)), 40);  // drops a@2, the oldest used
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(**cache.Get("a", 2, build(21)), 21);
  EXPECT_EQ(builds, 5);
  const absl::StatusOr<std::shared_ptr<const int>> failed =
      cache.Get("d", 1, [] { return absl::StatusOr<int>(absl::UnavailableError("busy")); });
  EXPECT_EQ(failed.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(**cache.Get("d", 1, build(50)), 50) << "a failure is not kept";
}

}  // namespace
}  // namespace plx::server::testing

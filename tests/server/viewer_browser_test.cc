// The viewer page in a real browser: plenoxd with --viewer, a Slam stream building a map and
// kept open, the page loaded in headless Chromium (tests/server/viewer_browser.py drives it
// over the DevTools pipe; WebGL on SwiftShader). It must draw the map (non-background pixels in
// the 3D view), show the stream's camera and path in its colour, follow the path as it grows
// without a reload, and show a render when the camera is clicked. The screenshot goes to
// $PLX_VIEWER_SCREENSHOT when set (docs/images/viewer.png is made this way). A second test
// clicks the page's Mesh toggle on a saved map and checks that the mesh is drawn; a third picks
// a level of detail, so the page loads /viewer/api/mesh.glb through three.js's GLTFLoader, and
// checks that the loader saw exactly the vertices and triangles the file declares (the
// "opens in three.js" evidence for the GLB files Export and the viewer write).
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/formats/glb_mesh.h"
#include "core/io/image_io.h"
#include "tests/server/viewer_fixture.h"

#ifndef PLX_SOURCE_DIR
#error "PLX_SOURCE_DIR must name the source tree (tests/CMakeLists.txt)"
#endif

namespace plx::server::testing {
namespace {

// Debian's chromium, or $PLX_CHROMIUM; empty when there is none.
std::string FindChromium() {
  if (const char* env = std::getenv("PLX_CHROMIUM"); env != nullptr && *env != '\0') return env;
  for (const char* path : {"/usr/bin/chromium", "/usr/bin/chromium-browser"}) {
    if (std::filesystem::exists(path)) return path;
  }
  return "";
}

// Runs `command`, returning its exit status and stdout.
int RunCommand(const std::string& command, std::string* output) {
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return -1;
  char buffer[4096];
  size_t n = 0;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) output->append(buffer, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The page's colours (web/viewer_assets): the 3D view's background and the first camera's.
constexpr int kBackground[3] = {0x15, 0x18, 0x1d};
constexpr int kFirstCamera[3] = {0xff, 0x2b, 0xd6};

bool Near(const uint8_t* rgb, const int* colour, int tolerance) {
  return std::abs(rgb[0] - colour[0]) <= tolerance && std::abs(rgb[1] - colour[1]) <= tolerance &&
         std::abs(rgb[2] - colour[2]) <= tolerance;
}

// Pixels of the screenshot's 3D view (between the two panels, 220 px and 260 px wide,
// viewer.css): all, those not of the background, those of the first camera's colour.
struct ViewPixels {
  int64_t total = 0, drawn = 0, camera = 0;
};

ViewPixels CountViewPixels(const cv::Mat& rgb_image) {  // RGB order (core/io/image_io.h)
  ViewPixels count;
  const int x0 = 230, x1 = rgb_image.cols - 270, y0 = 40, y1 = rgb_image.rows - 10;
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const cv::Vec3b& p = rgb_image.at<cv::Vec3b>(y, x);
      const uint8_t rgb[3] = {p[0], p[1], p[2]};
      ++count.total;
      count.drawn += !Near(rgb, kBackground, 12);
      count.camera += Near(rgb, kFirstCamera, 40);
    }
  }
  return count;
}

// The page's state line (viewer_browser.py prints the body's data attributes as JSON).
nlohmann::json PageState(const std::string& output) {
  const size_t start = output.rfind('{');
  return start == std::string::npos
             ? nlohmann::json()
             : nlohmann::json::parse(output.substr(start), nullptr, /*allow_exceptions=*/false);
}

int64_t StateNumber(const nlohmann::json& state, const char* key) {
  if (!state.is_object() || !state.contains(key) || !state[key].is_string()) return -1;
  return std::atoll(state[key].get<std::string>().c_str());
}

TEST(ViewerBrowserTest, PageDrawsTheMapAndALiveSlamCamera) {
  PLX_SKIP_WITHOUT_THREE_JS();
  const std::string chromium = FindChromium();
  if (chromium.empty()) {
    GTEST_SKIP() << "no chromium (Debian's package; scripts/install_deps.sh installs it, or set "
                    "$PLX_CHROMIUM)";
  }
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartTestDaemon(ViewerDaemonOptions("plx_srv_viewer_browser"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  OpenSlamStream stream(*(*started)->stub, "live", ViewerSlamOptions());
  ASSERT_TRUE(stream.Advance(12));
  ASSERT_GE(stream.keyframes(), 1);
  // The stream goes on while the page is open: the page must follow without a reload.
  std::atomic<bool> stop{false};
  std::thread walker([&] {
    while (!stop && stream.Advance(1)) absl::SleepFor(absl::Milliseconds(300));
  });

  const std::string shot = plx::testing::MakeTempDir("plx_srv_viewer_shot") + "/viewer.png";
  const std::string command = absl::StrCat(
      "/usr/bin/python3 ", PLX_SOURCE_DIR, "/tests/server/viewer_browser.py --chromium ",
      chromium, " --url 'http://127.0.0.1:", port, "/viewer/#map=live' --out ", shot,
      " --min-points 500 --min-cameras 1 --min-path 5 --path-grows --click-camera"
      " --timeout 60");
  std::string state;
  const int status = RunCommand(command, &state);
  stop = true;
  walker.join();
  const grpc::Status closed = stream.Close();
  EXPECT_TRUE(closed.ok()) << Describe(closed);
  ASSERT_EQ(status, 0) << "viewer_browser.py: " << state;
  std::printf("page state: %s", state.c_str());

  absl::StatusOr<cv::Mat> decoded = DecodeColorFile(shot);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const ViewPixels view = CountViewPixels(*decoded);
  ASSERT_GT(view.total, 0);
  const int64_t drawn = view.drawn, camera = view.camera, total = view.total;
  std::printf("3D view: %.1f%% drawn, %lld pixels in the camera's colour\n",
              100.0 * drawn / total, static_cast<long long>(camera));
  EXPECT_GT(drawn, total / 20) << "the map was not drawn";
  EXPECT_GT(camera, 30) << "the SLAM camera's marker and path are not in view";

  if (const char* keep = std::getenv("PLX_VIEWER_SCREENSHOT"); keep != nullptr && *keep) {
    std::error_code ec;
    std::filesystem::copy_file(shot, keep, std::filesystem::copy_options::overwrite_existing, ec);
    EXPECT_FALSE(ec) << keep << ": " << ec.message();
  }
}

// The Points / Mesh toggle: the page fetches /viewer/api/mesh and draws it (lit, vertex colours)
// in place of the points.
TEST(ViewerBrowserTest, MeshToggleDrawsTheMesh) {
  PLX_SKIP_WITHOUT_THREE_JS();
  const std::string chromium = FindChromium();
  if (chromium.empty()) GTEST_SKIP() << "no chromium";
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_viewer_browser_mesh"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  const std::string shot = plx::testing::MakeTempDir("plx_srv_viewer_mesh_shot") + "/mesh.png";
  const std::string command = absl::StrCat(
      "/usr/bin/python3 ", PLX_SOURCE_DIR, "/tests/server/viewer_browser.py --chromium ",
      chromium, " --url 'http://127.0.0.1:", port, "/viewer/#map=room' --out ", shot,
      " --min-points 500 --mesh --min-faces 1000 --timeout 40");
  std::string state;
  const int status = RunCommand(command, &state);
  ASSERT_EQ(status, 0) << "viewer_browser.py: " << state;
  std::printf("page state: %s", state.c_str());
  EXPECT_NE(state.find("\"mode\": \"mesh\""), std::string::npos) << state;
  EXPECT_NE(state.find("\"points\": \"0\""), std::string::npos)
      << "the points were replaced by the mesh: " << state;
  // The full mesh, as glTF through GLTFLoader: the triangles the viewer's PLY mesh has.
  EXPECT_NE(state.find("\"meshFormat\": \"glb\""), std::string::npos) << state;
  const HttpAnswer ply = HttpGetAnswer(port, "/viewer/api/mesh?map=room");
  ASSERT_EQ(ply.status, 200);
  const size_t faces_at = ply.headers.find("x-faces: ");
  ASSERT_NE(faces_at, std::string::npos) << ply.headers;
  EXPECT_EQ(StateNumber(PageState(state), "faces"), std::atoll(ply.headers.c_str() + faces_at + 9))
      << state;

  absl::StatusOr<cv::Mat> decoded = DecodeColorFile(shot);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const ViewPixels view = CountViewPixels(*decoded);
  ASSERT_GT(view.total, 0);
  const int64_t drawn = view.drawn, total = view.total;
  std::printf("3D view (mesh): %.1f%% drawn\n", 100.0 * drawn / total);
  EXPECT_GT(drawn, total / 10) << "the mesh was not drawn";
}

// A level of detail through three.js's GLTFLoader: the page asks for mesh.glb at 2000
// triangles, and what the loader built has exactly the vertices and triangles of that file
// (fetched here too), at most 2000, with the file's unlit material and vertex colours.
TEST(ViewerBrowserTest, ALevelOfDetailLoadsThroughGltfLoader) {
  PLX_SKIP_WITHOUT_THREE_JS();
  const std::string chromium = FindChromium();
  if (chromium.empty()) GTEST_SKIP() << "no chromium";
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_viewer_browser_glb"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  constexpr int kBudget = 2000;
  const std::string shot = plx::testing::MakeTempDir("plx_srv_viewer_glb_shot") + "/glb.png";
  const std::string command = absl::StrCat(
      "/usr/bin/python3 ", PLX_SOURCE_DIR, "/tests/server/viewer_browser.py --chromium ",
      chromium, " --url 'http://127.0.0.1:", port, "/viewer/#map=room' --out ", shot,
      " --min-points 500 --mesh --lod ", kBudget, " --min-faces 100 --timeout 40");
  std::string output;
  const int status = RunCommand(command, &output);
  ASSERT_EQ(status, 0) << "viewer_browser.py: " << output;
  std::printf("page state: %s", output.c_str());
  const nlohmann::json state = PageState(output);
  ASSERT_TRUE(state.is_object()) << output;
  EXPECT_EQ(state.value("meshFormat", ""), "glb");
  EXPECT_EQ(state.value("lodTriangles", ""), absl::StrCat(kBudget));
  EXPECT_EQ(state.value("material", ""), "MeshBasicMaterial") << "KHR_materials_unlit";
  EXPECT_EQ(state.value("vertexColors", ""), "true");

  // The same file, as the page fetched it (the map's version has not changed).
  const HttpAnswer glb =
      HttpGetAnswer(port, absl::StrCat("/viewer/api/mesh.glb?map=room&triangles=", kBudget));
  ASSERT_EQ(glb.status, 200) << glb.body.substr(0, 200);
  const absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(glb.body);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_LE(info->triangles, kBudget);
  EXPECT_GT(info->full_triangles, info->triangles);
  EXPECT_EQ(StateNumber(state, "faces"), info->triangles) << "GLTFLoader's triangles";
  EXPECT_EQ(StateNumber(state, "vertices"), info->vertices) << "GLTFLoader's vertices";
  EXPECT_EQ(StateNumber(state, "fullFaces"), info->full_triangles);
  std::printf("GLTFLoader: %lld vertices, %lld triangles (a level of detail of %lld)\n",
              static_cast<long long>(StateNumber(state, "vertices")),
              static_cast<long long>(StateNumber(state, "faces")),
              static_cast<long long>(info->full_triangles));

  absl::StatusOr<cv::Mat> decoded = DecodeColorFile(shot);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const ViewPixels view = CountViewPixels(*decoded);
  ASSERT_GT(view.total, 0);
  std::printf("3D view (GLB at %d triangles): %.1f%% drawn\n", kBudget,
              100.0 * view.drawn / view.total);
  EXPECT_GT(view.drawn, view.total / 10) << "the level of detail was not drawn";
}

}  // namespace
}  // namespace plx::server::testing

// Black-box tests of `plenox --server HOST:PORT ...` against the real plenoxd binary, started as
// a subprocess on a free port with a scratch data directory: map -> maps -> track -> render ->
// export -> save/load on a small synthetic sequence, the error paths (unknown map, unreachable
// daemon, malformed --server, token files), bearer-token authentication, and a clean SIGTERM.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_format.h"
#include "app/make_backend.h"
#include "clients/plenox/cli_common.h"
#include "tests/clients/cli_runner.h"
#include "tests/clients/mesh_output.h"
#include "tests/clients/remote_daemon.h"
#include "tests/test_util.h"

namespace plx {
namespace remote_cli_test {
using cli::kExitOk;
using cli::kExitFailure;
using cli::kExitUsage;

namespace fs = std::filesystem;
using plx::testing::CommandResult;
#ifdef PLENOXD_BINARY
using plx::testing::DaemonProcess;
using plx::testing::RemoteSuite;
#endif
using plx::testing::FlatJson;
using plx::testing::JsonNumber;
using plx::testing::LastLine;
using plx::testing::LastLineJson;
using plx::testing::JoinFields;
using plx::testing::ReadRows;
using plx::testing::ListTree;
using plx::testing::ParseFlatJson;
using plx::testing::ReadFileToString;
using plx::testing::RunPlenox;
using plx::testing::ScopedTempDir;
using plx::testing::UnusedPort;
using plx::testing::WriteStringToFile;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::Not;
using ::testing::StartsWith;



TEST(RemoteCliBadInputTest, ServerWithoutPortIsUsageError) {
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--server", "127.0.0.1", "maps"},
        std::vector<std::string>{"--server", "127.0.0.1:", "maps"},
        std::vector<std::string>{"--server", "127.0.0.1:99999", "maps"},
        std::vector<std::string>{"--server=localhost", "maps"}}) {
    const CommandResult r = RunPlenox(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_THAT(r.err, AllOf(StartsWith("plenox"), HasSubstr("HOST:PORT"))) << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  }
  const CommandResult bare = RunPlenox({"--server"});
  EXPECT_EQ(bare.exit_code, kExitUsage) << bare.Describe();
  EXPECT_THAT(bare.err, HasSubstr("--server needs a value")) << bare.Describe();
}

#ifndef PLX_WITH_SERVER

TEST(RemoteCliBadInputTest, ServerNeedsABuildWithGrpc) {
  const CommandResult r = RunPlenox({"--server", "127.0.0.1:50051", "maps"});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr("needs a plenox built with gRPC")) << r.Describe();
}

#else

TEST(RemoteCliBadInputTest, UnreachableDaemonFailsFastWithAClearMessage) {
  const int port = UnusedPort();
  ASSERT_GT(port, 0);
  const std::string server = "127.0.0.1:" + std::to_string(port);
  const CommandResult r = RunPlenox({"--server", server, "maps"}, "", /*timeout_s=*/30.0);
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, StartsWith("plenox maps: cannot reach " + server)) << r.Describe();
  EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  EXPECT_LT(r.seconds, 10.0) << r.Describe();
}

TEST(RemoteCliBadInputTest, TokenFileProblemsAreUsageErrors) {
  ScopedTempDir work("plenox_remote_bad");
  const std::string server = "127.0.0.1:" + std::to_string(UnusedPort());
  // Missing file: reported before anything goes over the network.
  const CommandResult missing =
      RunPlenox({"--server", server, "--token-file", work / "no_such_token", "maps"});
  EXPECT_EQ(missing.exit_code, kExitUsage) << missing.Describe();
  EXPECT_THAT(missing.err, AllOf(HasSubstr("--token-file"), HasSubstr("no_such_token")))
      << missing.Describe();
  WriteStringToFile(work / "empty_token", " \n");
  const CommandResult empty =
      RunPlenox({"--server", server, "--token-file", work / "empty_token", "maps"});
  EXPECT_EQ(empty.exit_code, kExitUsage) << empty.Describe();
  EXPECT_THAT(empty.err, HasSubstr("empty")) << empty.Describe();
  // Without --server there is nothing to send it to.
  const CommandResult alone = RunPlenox({"--token-file", work / "empty_token", "maps"});
  EXPECT_EQ(alone.exit_code, kExitUsage) << alone.Describe();
  EXPECT_THAT(alone.err, HasSubstr("--server")) << alone.Describe();
}

TEST(RemoteCliBadInputTest, CommandsThatNeedOrRefuseADaemonSaySo) {
  for (const char* command : {"maps", "save", "load", "info"}) {
    SCOPED_TRACE(command);
    const CommandResult help = RunPlenox({command, "--help"});
    EXPECT_EQ(help.exit_code, kExitOk) << help.Describe();
    EXPECT_THAT(help.out, StartsWith(std::string("usage: plenox ") + command)) << help.Describe();
    std::vector<std::string> args = {command};
    if (std::string(command) != "maps" && std::string(command) != "info") {
      args.insert(args.end(), {"--map", "m"});
    }
    const CommandResult r = RunPlenox(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_THAT(r.err, HasSubstr("--server HOST:PORT")) << r.Describe();
  }
  ScopedTempDir work("plenox_remote_bad");
  const CommandResult synth =
      RunPlenox({"--server", "127.0.0.1:50051", "synth", "--out", "never_written"}, work.path());
  EXPECT_EQ(synth.exit_code, kExitUsage) << synth.Describe();
  EXPECT_THAT(synth.err, HasSubstr("in-process only")) << synth.Describe();
  EXPECT_THAT(ListTree(work.path()), IsEmpty());
}

#endif  // PLX_WITH_SERVER

#ifdef PLENOXD_BINARY

// `maps --json` prints one object per map and line.
std::optional<FlatJson> MapJson(const CommandResult& r, const std::string& name) {
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) {
    const std::optional<FlatJson> json = ParseFlatJson(line);
    if (json && json->count("name") && json->at("name").text == name) return json;
  }
  return std::nullopt;
}

constexpr int kFrames = 30;
constexpr int kWidth = 96;
constexpr int kHeight = 72;
constexpr char kMap[] = "seq";

// One daemon, one synthetic sequence and one map for the whole suite.
class RemoteCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    suite_ = new RemoteSuite("plenox_remote", kFrames, kWidth, kHeight, {});
    map_run_ = new CommandResult();
    if (suite_->Ready()) {
      // Keyframes 0, 10, 20 and 60 iterations, as the in-process end-to-end test.
      *map_run_ = Remote({"map", "--dataset", suite_->dataset(), "--name", kMap, "--every", "10",
                          "--voxel-size", "0.04", "--iterations-per-keyframe", "20", "--json"},
                         "", /*timeout_s=*/120.0);
    }
    dataset_ = &suite_->dataset();
    daemon_ = &suite_->daemon();
  }
  static void TearDownTestSuite() {
    delete map_run_;
    delete suite_;  // SIGTERM drains and saves; a clean exit is part of the contract
  }

  void SetUp() override {
    ASSERT_TRUE(suite_->Ready());
    ASSERT_EQ(map_run_->exit_code, kExitOk) << map_run_->Describe() << "\n" << daemon_->Log();
  }

  static CommandResult Remote(std::vector<std::string> args, const std::string& cwd = "",
                              double timeout_s = 60.0) {
    return suite_->Remote(std::move(args), cwd, timeout_s);
  }

  static RemoteSuite* suite_;
  static const std::string* dataset_;
  static const DaemonProcess* daemon_;
  static CommandResult* map_run_;
};

RemoteSuite* RemoteCliTest::suite_ = nullptr;
const std::string* RemoteCliTest::dataset_ = nullptr;
const DaemonProcess* RemoteCliTest::daemon_ = nullptr;
CommandResult* RemoteCliTest::map_run_ = nullptr;

TEST_F(RemoteCliTest, MapReportsTheDaemonsSummary) {
  const FlatJson json = LastLineJson(*map_run_);
  EXPECT_EQ(json.at("map").text, kMap);
  EXPECT_EQ(json.at("server").text, daemon_->address());
  EXPECT_EQ(JsonNumber(json, "created").value_or(-1), 1);
  EXPECT_EQ(JsonNumber(json, "keyframes").value_or(-1), 3);
  EXPECT_EQ(JsonNumber(json, "iterations").value_or(-1), 60);
  EXPECT_GT(JsonNumber(json, "map_version").value_or(-1), 1);
  EXPECT_GT(JsonNumber(json, "bricks").value_or(-1), 0);
  EXPECT_GT(JsonNumber(json, "map_mb").value_or(-1), 0.0);
  // The daemon's training error on the last batch, when it reports one (null otherwise).
  ASSERT_TRUE(json.count("train_psnr"));
  if (json.at("train_psnr").text != "null") {
    EXPECT_GT(JsonNumber(json, "train_psnr").value_or(-1), 20.0);
  }
  EXPECT_GT(JsonNumber(json, "seconds").value_or(-1), 0.0);
}

TEST_F(RemoteCliTest, MapsListsTheMap) {
  const CommandResult table = Remote({"maps"});
  ASSERT_EQ(table.exit_code, kExitOk) << table.Describe();
  EXPECT_THAT(table.out, AllOf(StartsWith("NAME"), HasSubstr("KEYFRAMES"), HasSubstr("\nseq ")))
      << table.Describe();

  const CommandResult listed = Remote({"maps", "--json"});
  ASSERT_EQ(listed.exit_code, kExitOk) << listed.Describe();
  const std::optional<FlatJson> json = MapJson(listed, kMap);
  ASSERT_TRUE(json.has_value()) << listed.Describe();
  EXPECT_EQ(JsonNumber(*json, "keyframes").value_or(-1), 3);
  EXPECT_NEAR(JsonNumber(*json, "voxel_size").value_or(-1), 0.04, 1e-6);
  EXPECT_GT(JsonNumber(*json, "bricks").value_or(-1), 0);
  EXPECT_EQ(json->at("mapping").text, "false");
}

// Lock-step tracking: one estimate per frame, none dropped, within a centimetre of the ground
// truth, and the same trajectory as in-process tracking on the daemon's saved map.
TEST_F(RemoteCliTest, TrackWritesEveryFrameAndMatchesInProcessTracking) {
  ScopedTempDir work("plenox_remote_track");
  const std::string trajectory = work / "remote.txt";
  const CommandResult r =
      Remote({"track", "--map", kMap, "--dataset", *dataset_, "--out", trajectory, "--rays",
              "1024", "--json"},
             "", /*timeout_s=*/120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(JsonNumber(json, "frames").value_or(-1), kFrames);
  EXPECT_EQ(JsonNumber(json, "lost").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "dropped").value_or(-1), 0);
  EXPECT_TRUE(JsonNumber(json, "degraded").has_value());
  EXPECT_GT(JsonNumber(json, "ms_per_frame_median").value_or(-1), 0.0);
  EXPECT_GE(JsonNumber(json, "ms_per_frame_p95").value_or(-1),
            JsonNumber(json, "ms_per_frame_median").value_or(-1));
  EXPECT_EQ(json.at("server").text, daemon_->address());
  const auto poses = ReadRows(trajectory);
  ASSERT_EQ(poses.size(), static_cast<size_t>(kFrames));

  const CommandResult scored = RunPlenox(
      {"eval-traj", "--est", trajectory, "--gt", *dataset_ + "/groundtruth.txt", "--json"});
  ASSERT_EQ(scored.exit_code, kExitOk) << scored.Describe();
  const FlatJson ate = LastLineJson(scored);
  EXPECT_EQ(JsonNumber(ate, "matched").value_or(-1), kFrames);
  EXPECT_LT(JsonNumber(ate, "ate_rmse_m").value_or(1), 0.01);

  // The same frames through the in-process tracker on the map the daemon saves.
  const CommandResult saved = Remote({"save", "--map", kMap});
  ASSERT_EQ(saved.exit_code, kExitOk) << saved.Describe();
  const std::string local = work / "local.txt";
  const CommandResult in_process =
      RunPlenox({"track", "--map", daemon_->data_dir() + "/seq.plx", "--dataset", *dataset_,
                 "--out", local, "--rays", "1024", "--threads", "2", "--quiet"},
                "", /*timeout_s=*/120.0);
  ASSERT_EQ(in_process.exit_code, kExitOk) << in_process.Describe();
  const auto local_poses = ReadRows(local);
  ASSERT_EQ(local_poses.size(), poses.size());
  double worst = 0.0;
  for (size_t i = 0; i < poses.size(); ++i) {
    ASSERT_EQ(poses[i].size(), 8u);
    ASSERT_EQ(local_poses[i].size(), 8u);
    EXPECT_EQ(poses[i][0], local_poses[i][0]) << "timestamps differ at frame " << i;
    for (size_t c = 1; c < 8; ++c) {
      worst = std::max(worst, std::abs(std::stod(poses[i][c]) - std::stod(local_poses[i][c])));
    }
  }
  // Measured: identical to the 9 digits written (same frames after the PNG round trip, same
  // map, same tracker, same thread count).
  EXPECT_LT(worst, 1e-6) << "remote and in-process trajectories differ by up to " << worst;
}

TEST_F(RemoteCliTest, RenderWritesPngsOfTheRequestedSize) {
  constexpr int kFrame = 15;  // between keyframes 10 and 20
  const auto intrinsics_rows = ReadRows(*dataset_ + "/intrinsics.txt");
  ASSERT_EQ(intrinsics_rows.size(), 1u);
  const std::string intrinsics = JoinFields(intrinsics_rows[0], 0, 6);
  const auto gt = ReadRows(*dataset_ + "/groundtruth.txt");
  ASSERT_GT(gt.size(), static_cast<size_t>(kFrame));
  const std::string pose = JoinFields(gt[kFrame], 1, 7);

  ScopedTempDir work("plenox_remote_render");
  const CommandResult r = Remote({"render", "--map", kMap, "--pose", pose, "--intrinsics",
                                  intrinsics, "--color", "c.png", "--depth", "d.png"},
                                 work.path());
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.out, AllOf(HasSubstr("c.png"), HasSubstr("d.png"))) << r.Describe();
  // Nothing but the two images: the temporary files were renamed.
  EXPECT_EQ(ListTree(work.path()), (std::set<std::string>{"c.png", "d.png"}));
  const cv::Mat color = cv::imread(work / "c.png", cv::IMREAD_UNCHANGED);
  const cv::Mat depth = cv::imread(work / "d.png", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(color.empty());
  ASSERT_FALSE(depth.empty());
  EXPECT_EQ(color.type(), CV_8UC3);
  EXPECT_EQ(depth.type(), CV_16UC1);
  EXPECT_EQ(color.cols, kWidth);
  EXPECT_EQ(color.rows, kHeight);
  EXPECT_EQ(depth.cols, kWidth);
  EXPECT_EQ(depth.rows, kHeight);
  EXPECT_GT(cv::countNonZero(depth), kWidth * kHeight / 2);

  // Only a colour image when only --color is given.
  ScopedTempDir only_color("plenox_remote_render");
  const CommandResult c = Remote({"render", "--map", kMap, "--pose", pose, "--intrinsics",
                                  intrinsics, "--color", "c.png"},
                                 only_color.path());
  ASSERT_EQ(c.exit_code, kExitOk) << c.Describe();
  EXPECT_EQ(ListTree(only_color.path()), (std::set<std::string>{"c.png"}));
}

TEST_F(RemoteCliTest, ExportWritesAPlyWithPoints) {
  ScopedTempDir work("plenox_remote_export");
  const CommandResult r =
      Remote({"export", "--map", kMap, "--out", "cloud.ply", "--json"}, work.path());
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_EQ(ListTree(work.path()), (std::set<std::string>{"cloud.ply"}));
  const std::string ply = ReadFileToString(work / "cloud.ply");
  const size_t header_end = ply.find("end_header\n");
  ASSERT_NE(header_end, std::string::npos);
  const std::string header = ply.substr(0, header_end);
  EXPECT_THAT(header, AllOf(StartsWith("ply\n"), HasSubstr("format binary_little_endian 1.0\n"),
                            HasSubstr("property float x\n"), HasSubstr("property uchar blue\n")));
  const std::string key = "\nelement vertex ";
  const size_t at = header.find(key);
  ASSERT_NE(at, std::string::npos) << header;
  const long vertices = std::stol(header.substr(at + key.size()));
  EXPECT_GT(vertices, 0);
  // x y z float + r g b uchar = 15 bytes per point.
  EXPECT_EQ(ply.size(), header_end + std::string("end_header\n").size() + 15u * vertices);
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(JsonNumber(json, "points").value_or(-1), vertices);
  EXPECT_EQ(JsonNumber(json, "bytes").value_or(-1), static_cast<double>(ply.size()));
}

// --mesh: the daemon builds the mesh; the file reads back as one, the JSON counts match it.
TEST_F(RemoteCliTest, ExportMeshWritesAPlyMesh) {
  ScopedTempDir work("plenox_remote_mesh");
  const CommandResult r = Remote(
      {"export", "--map", kMap, "--out", "mesh.ply", "--mesh", "--min-component", "10", "--json"},
      work.path());
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_EQ(ListTree(work.path()), (std::set<std::string>{"mesh.ply"}));
  EXPECT_GT(plx::testing::ExpectMeshFileMatchingJson(work / "mesh.ply", r).num_triangles(), 100);
  // A limit below the mesh: the daemon's RESOURCE_EXHAUSTED, no file.
  ScopedTempDir capped("plenox_remote_mesh_cap");
  const CommandResult c = Remote(
      {"export", "--map", kMap, "--out", "mesh.ply", "--mesh", "--max-triangles", "5"},
      capped.path());
  EXPECT_EQ(c.exit_code, kExitFailure) << c.Describe();
  EXPECT_THAT(c.err, HasSubstr("max_triangles")) << c.Describe();
  EXPECT_THAT(ListTree(capped.path()), IsEmpty());
}

// --format glb and --lod-triangles through the daemon: the GLB the daemon built, counts read
// from its JSON chunk into the summary, at most the budget.
TEST_F(RemoteCliTest, ExportMeshWritesGlbAtALevelOfDetail) {
  ScopedTempDir work("plenox_remote_glb");
  const CommandResult full =
      Remote({"export", "--map", kMap, "--out", "mesh.glb", "--mesh", "--json"}, work.path());
  ASSERT_EQ(full.exit_code, kExitOk) << full.Describe();
  const int64_t triangles =
      plx::testing::ExpectGlbFileMatchingJson(work / "mesh.glb", full).mesh.num_triangles();
  ASSERT_GT(triangles, 100);
  const int64_t budget = triangles / 10;
  const CommandResult lod = Remote({"export", "--map", kMap, "--out", "lod.glb", "--mesh",
                                    "--lod-triangles", std::to_string(budget), "--json"},
                                   work.path());
  ASSERT_EQ(lod.exit_code, kExitOk) << lod.Describe();
  EXPECT_LE(plx::testing::ExpectGlbFileMatchingJson(work / "lod.glb", lod).mesh.num_triangles(),
            budget);
  EXPECT_EQ(JsonNumber(LastLineJson(lod), "full_faces").value_or(-1), triangles);
  EXPECT_GT(JsonNumber(LastLineJson(lod), "lod_error_m").value_or(-1), 0.0);
  const CommandResult ply = Remote({"export", "--map", kMap, "--out", "lod.ply", "--mesh",
                                    "--lod-triangles", std::to_string(budget), "--json"},
                                   work.path());
  ASSERT_EQ(ply.exit_code, kExitOk) << ply.Describe();
  EXPECT_LE(plx::testing::ExpectMeshFileMatchingJson(work / "lod.ply", ply).num_triangles(),
            budget);
  EXPECT_EQ(ListTree(work.path()), (std::set<std::string>{"mesh.glb", "lod.glb", "lod.ply"}));
}

// --bbox through the daemon: the region field, the box's triangles in either format (the file
// recording the box, which the CLI checks), and an empty box refused before any call.
TEST_F(RemoteCliTest, ExportMeshOfABoxOfTheMap) {
  ScopedTempDir work("plenox_remote_bbox");
  const CommandResult full =
      Remote({"export", "--map", kMap, "--out", "mesh.glb", "--mesh", "--json"}, work.path());
  ASSERT_EQ(full.exit_code, kExitOk) << full.Describe();
  const plx::testing::GlbFile whole =
      plx::testing::ExpectGlbFileMatchingJson(work / "mesh.glb", full);
  ASSERT_GT(whole.mesh.num_triangles(), 100);
  const double middle = 0.5 * (whole.position_min[0] + whole.position_max[0]);
  const std::string box = absl::StrFormat("-100,-100,-100,%.17g,100,100", middle);
  int64_t faces = -1;
  for (const char* out : {"half.glb", "half.ply"}) {
    SCOPED_TRACE(out);
    const CommandResult half =
        Remote({"export", "--map", kMap, "--out", out, "--mesh", "--bbox", box, "--json"},
               work.path());
    ASSERT_EQ(half.exit_code, kExitOk) << half.Describe();
    const plx::TriangleMesh mesh =
        std::string(out) == "half.glb"
            ? plx::testing::ExpectGlbFileMatchingJson(work / out, half).mesh
            : plx::testing::ExpectMeshFileMatchingJson(work / out, half);
    EXPECT_GT(mesh.num_triangles(), 0);
    EXPECT_LT(mesh.num_triangles(), whole.mesh.num_triangles());
    if (faces >= 0) EXPECT_EQ(mesh.num_triangles(), faces) << "the same box in either format";
    faces = mesh.num_triangles();
    for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
      EXPECT_LE(mesh.positions[3 * v], middle + 0.02 + 1e-4);  // half the map's 4 cm voxel
    }
    EXPECT_EQ(LastLineJson(half).count("bbox"), 1u) << half.Describe();
  }
  const CommandResult refused = Remote(
      {"export", "--map", kMap, "--out", "x.glb", "--mesh", "--bbox", "0,0,0,1,1,0"},
      work.path());
  EXPECT_EQ(refused.exit_code, kExitUsage) << refused.Describe();
  EXPECT_EQ(ListTree(work.path()),
            (std::set<std::string>{"mesh.glb", "half.glb", "half.ply"}));
}

TEST_F(RemoteCliTest, SaveWritesTheMapFileAndLoadReadsItBack) {
  const CommandResult saved = Remote({"save", "--map", kMap, "--json"});
  ASSERT_EQ(saved.exit_code, kExitOk) << saved.Describe();
  EXPECT_EQ(LastLineJson(saved).at("dirty").text, "false");
  EXPECT_TRUE(fs::is_regular_file(daemon_->data_dir() + "/seq.plx"));
  const CommandResult loaded = Remote({"load", "--map", kMap});
  ASSERT_EQ(loaded.exit_code, kExitOk) << loaded.Describe();
  EXPECT_THAT(loaded.out, AllOf(StartsWith("loaded \"seq\""), HasSubstr("bricks")))
      << loaded.Describe();
  const CommandResult listed = Remote({"maps", "--json"});
  ASSERT_EQ(listed.exit_code, kExitOk) << listed.Describe();
  const std::optional<FlatJson> json = MapJson(listed, kMap);
  ASSERT_TRUE(json.has_value()) << listed.Describe();
  EXPECT_GT(JsonNumber(*json, "bricks").value_or(-1), 0);
}

TEST_F(RemoteCliTest, MappingIntoAnExistingMapKeepsGoingAndSaysSo) {
  const std::vector<std::string> args = {"map", "--dataset", *dataset_, "--name", "again",
                                         "--every", "100", "--voxel-size", "0.08",
                                         "--iterations-per-keyframe", "5", "--quiet", "--json"};
  const CommandResult first = Remote(args);
  ASSERT_EQ(first.exit_code, kExitOk) << first.Describe();
  EXPECT_EQ(JsonNumber(LastLineJson(first), "created").value_or(-1), 1);
  const CommandResult second = Remote(args);
  ASSERT_EQ(second.exit_code, kExitOk) << second.Describe();
  EXPECT_THAT(second.err, AllOf(HasSubstr("already exists"), HasSubstr("mapping into it")))
      << second.Describe();
  const FlatJson json = LastLineJson(second);
  EXPECT_EQ(JsonNumber(json, "created").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "map_keyframes").value_or(-1), 2);
}

TEST_F(RemoteCliTest, UnknownMapIsNotFoundAndWritesNothing) {
  ScopedTempDir work("plenox_remote_missing");
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"track", {"track", "--map", "nosuch", "--dataset", *dataset_, "--out", "t.txt"}},
      {"render",
       {"render", "--map", "nosuch", "--pose", "0 0 0 0 0 0 1", "--intrinsics",
        "80 80 48 36 96 72", "--color", "c.png", "--depth", "d.png"}},
      {"export", {"export", "--map", "nosuch", "--out", "cloud.ply"}},
      {"save", {"save", "--map", "nosuch"}},
      {"load", {"load", "--map", "nosuch"}},
  };
  for (const auto& [command, args] : cases) {
    SCOPED_TRACE(command);
    const CommandResult r = Remote(args, work.path());
    EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
    EXPECT_THAT(r.err, AllOf(StartsWith("plenox " + command + ": "), HasSubstr("nosuch"),
                             HasSubstr("NOT_FOUND")))
        << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
    EXPECT_THAT(ListTree(work.path()), IsEmpty()) << r.Describe();
  }
}

// An unwritable --timings is refused before any frame is streamed, so no tracking is lost.
TEST_F(RemoteCliTest, TimingsIntoAMissingFolderFailsBeforeTracking) {
  ScopedTempDir work("plenox_remote_timings");
  const CommandResult r = Remote({"track", "--map", kMap, "--dataset", *dataset_, "--out",
                                  "t.txt", "--timings", "no/such/folder/times.txt"},
                                 work.path());
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, AllOf(StartsWith("plenox track: "), HasSubstr("no/such/folder")))
      << r.Describe();
  EXPECT_THAT(r.err, Not(HasSubstr("tracking "))) << "frames were streamed\n" << r.Describe();
  EXPECT_THAT(ListTree(work.path()), IsEmpty()) << r.Describe();
}

// A daemon with --auth-token-file: every call needs "authorization: Bearer <token>".
TEST(RemoteCliAuthTest, TheTokenFromTokenFileIsRequiredAndSent) {
  ScopedTempDir root("plenox_remote_auth");
  WriteStringToFile(root / "token", "s3cret-token\n");
  WriteStringToFile(root / "wrong", "not-the-token\n");
  DaemonProcess daemon(root.path(), {"--auth-token-file", root / "token"});
  ASSERT_TRUE(daemon.running()) << daemon.Log();
  const std::string server = daemon.address();

  const CommandResult without = RunPlenox({"--server", server, "maps"});
  EXPECT_EQ(without.exit_code, kExitFailure) << without.Describe();
  EXPECT_THAT(without.err, AllOf(StartsWith("plenox maps: "), HasSubstr("UNAUTHENTICATED")))
      << without.Describe();
  EXPECT_THAT(without.out, IsEmpty());

  const CommandResult wrong =
      RunPlenox({"--server", server, "--token-file", root / "wrong", "save", "--map", "m"});
  EXPECT_EQ(wrong.exit_code, kExitFailure) << wrong.Describe();
  EXPECT_THAT(wrong.err, AllOf(StartsWith("plenox save: "), HasSubstr("UNAUTHENTICATED")))
      << wrong.Describe();

  const CommandResult right =
      RunPlenox({"--server", server, "--token-file", root / "token", "maps"});
  EXPECT_EQ(right.exit_code, kExitOk) << right.Describe();
  EXPECT_THAT(right.out, HasSubstr("no maps on " + server)) << right.Describe();
  // Authenticated, the daemon's own answer comes through.
  const CommandResult missing =
      RunPlenox({"--server", server, "--token-file=" + root / "token", "load", "--map", "m"});
  EXPECT_EQ(missing.exit_code, kExitFailure) << missing.Describe();
  EXPECT_THAT(missing.err, HasSubstr("NOT_FOUND")) << missing.Describe();

  EXPECT_EQ(daemon.Stop(), 0) << daemon.Log();
}

// A TLS daemon (a throwaway self-signed certificate for 127.0.0.1): reachable with --tls-ca,
// and a plaintext client gets the "cannot reach" message rather than a hang.
TEST(RemoteCliTlsTest, TlsCaLetsTheClientTalkToATlsDaemon) {
  const std::string openssl = "/usr/bin/openssl";
  if (!fs::exists(openssl)) GTEST_SKIP() << "needs " << openssl << " to make a certificate";
  ScopedTempDir root("plenox_remote_tls");
  const CommandResult made = plx::testing::RunCommand(
      openssl, {"req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", root / "key.pem",
                "-out", root / "cert.pem", "-subj", "/CN=localhost", "-addext",
                "subjectAltName=IP:127.0.0.1,DNS:localhost", "-days", "1"});
  ASSERT_EQ(made.exit_code, 0) << made.Describe();
  DaemonProcess daemon(root.path(),
                       {"--tls-cert", root / "cert.pem", "--tls-key", root / "key.pem"});
  ASSERT_TRUE(daemon.running()) << daemon.Log();

  const CommandResult tls =
      RunPlenox({"--server", daemon.address(), "--tls-ca", root / "cert.pem", "maps"});
  EXPECT_EQ(tls.exit_code, kExitOk) << tls.Describe();
  EXPECT_THAT(tls.out, HasSubstr("no maps on " + daemon.address())) << tls.Describe();
  EXPECT_THAT(tls.err, IsEmpty()) << tls.Describe();

  const CommandResult plain = RunPlenox({"--server", daemon.address(), "maps"});
  EXPECT_EQ(plain.exit_code, kExitFailure) << plain.Describe();
  EXPECT_THAT(plain.err, AllOf(StartsWith("plenox maps: cannot reach " + daemon.address()),
                               HasSubstr("--tls-ca")))
      << plain.Describe();

  const CommandResult missing_ca =
      RunPlenox({"--server", daemon.address(), "--tls-ca", root / "none.pem", "maps"});
  EXPECT_EQ(missing_ca.exit_code, kExitUsage) << missing_ca.Describe();
  EXPECT_THAT(missing_ca.err, HasSubstr("--tls-ca")) << missing_ca.Describe();

  EXPECT_EQ(daemon.Stop(), 0) << daemon.Log();
}

// plenoxd's device flags: bad values are usage errors (exit 2) before anything starts, and
// --backend cuda without CUDA stops at start (exit 1) with a message that names CUDA.
TEST(PlenoxdDeviceFlagsTest, BadBackendOrGpusStopsTheDaemonAtStart) {
  ScopedTempDir work("plenoxd_flags");
  const auto run = [&](const std::vector<std::string>& flags) {
    std::vector<std::string> args = {"--listen", "127.0.0.1:0", "--data-dir",
                                     work.path() + "/data"};
    args.insert(args.end(), flags.begin(), flags.end());
    return plx::testing::RunCommand(PLENOXD_BINARY, args, "", /*timeout_s=*/20.0);
  };
  const CommandResult help = plx::testing::RunCommand(PLENOXD_BINARY, {"--help"});
  EXPECT_EQ(help.exit_code, kExitOk) << help.Describe();
  EXPECT_THAT(help.out, AllOf(HasSubstr("--backend cpu|cuda|auto"), HasSubstr("--gpus all|0,1,..."),
                              HasSubstr("one worker per GPU")))
      << help.Describe();

  const struct {
    std::vector<std::string> flags;
    std::string says;
  } usage_errors[] = {
      {{"--backend", "gpu"}, "--backend must be cpu, cuda or auto, got \"gpu\""},
      {{"--gpus", "zero"}, "--gpus: expected \"all\" or device ids like 0,1; got \"zero\""},
      {{"--gpus", "-1"}, "--gpus"},
      {{"--gpus", "4096"}, "--gpus: device 4096 does not exist"},
      {{"--backend", "cpu", "--gpus", "0"}, "--gpus only applies with --backend cuda or auto"},
  };
  for (const auto& c : usage_errors) {
    const CommandResult r = run(c.flags);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_THAT(r.err, AllOf(StartsWith("plenoxd: "), HasSubstr(c.says))) << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  }

  if (CudaDeviceCount() == 0) {
    const CommandResult cuda = run({"--backend", "cuda"});
    EXPECT_EQ(cuda.exit_code, kExitFailure) << cuda.Describe();
    EXPECT_THAT(cuda.err, AllOf(StartsWith("plenoxd: --backend cuda: "), HasSubstr("CUDA")))
        << cuda.Describe();
    EXPECT_THAT(cuda.out, Not(HasSubstr("listening"))) << cuda.Describe();
  }
}

// plenoxd's secret files are checked before it listens: a certificate or key that is not PEM,
// or a token with a space inside, stops it with a usage error naming the file (a bad
// certificate used to surface as "cannot listen ... address in use").
TEST(PlenoxdSecretFlagsTest, BadTlsOrTokenFilesAreNamed) {
  ScopedTempDir work("plenoxd_secrets");
  WriteStringToFile(work / "cert.pem", "not a certificate\n");
  WriteStringToFile(work / "key.pem", "not a key\n");
  WriteStringToFile(work / "token", "two words\n");
  const auto run = [&](const std::vector<std::string>& flags) {
    std::vector<std::string> args = {"--listen", "127.0.0.1:0", "--data-dir",
                                     work.path() + "/data"};
    args.insert(args.end(), flags.begin(), flags.end());
    return plx::testing::RunCommand(PLENOXD_BINARY, args, "", /*timeout_s=*/20.0);
  };
  const CommandResult tls = run({"--tls-cert", work / "cert.pem", "--tls-key", work / "key.pem"});
  EXPECT_EQ(tls.exit_code, kExitUsage) << tls.Describe();
  EXPECT_THAT(tls.err, AllOf(HasSubstr(work / "cert.pem"), HasSubstr("not a PEM certificate"),
                             Not(HasSubstr("in use"))))
      << tls.Describe();
  const CommandResult token = run({"--auth-token-file", work / "token"});
  EXPECT_EQ(token.exit_code, kExitUsage) << token.Describe();
  EXPECT_THAT(token.err, AllOf(HasSubstr("--auth-token-file: " + work / "token"),
                               HasSubstr("printable ASCII without spaces")))
      << token.Describe();
}

// `plenox --server ... info`: the daemon's version and its CPU workers (--backend cpu): the
// interactive one and the mapping one.
TEST(RemoteCliInfoTest, InfoListsTheDevices) {
  ScopedTempDir work("plenox_remote_info");
  DaemonProcess daemon(work.path(), {"--backend", "cpu"});
  ASSERT_TRUE(daemon.running()) << daemon.Log();

  const CommandResult text = RunPlenox({"--server", daemon.address(), "info"});
  ASSERT_EQ(text.exit_code, kExitOk) << text.Describe();
  EXPECT_THAT(text.out, AllOf(StartsWith("plenoxd "), HasSubstr("on " + daemon.address()),
                              HasSubstr("backend cpu"), HasSubstr("0 maps"),
                              HasSubstr("2 devices"), HasSubstr("cpu (2 threads, interactive)"),
                              HasSubstr("cpu (2 threads, mapping, nice +10)")))
      << text.Describe();

  const CommandResult json = RunPlenox({"--server", daemon.address(), "info", "--json"});
  ASSERT_EQ(json.exit_code, kExitOk) << json.Describe();
  std::istringstream lines(json.out);
  std::string server_line, tracking_line, mapping_line, extra;
  std::getline(lines, server_line);
  std::getline(lines, tracking_line);
  std::getline(lines, mapping_line);
  EXPECT_FALSE(std::getline(lines, extra)) << json.Describe();
  const std::optional<FlatJson> server = ParseFlatJson(server_line);
  ASSERT_TRUE(server.has_value()) << json.Describe();
  EXPECT_EQ(server->at("backend").text, "cpu");
  EXPECT_EQ(JsonNumber(*server, "maps"), 0.0);
  EXPECT_EQ(JsonNumber(*server, "devices"), 2.0);
  EXPECT_FALSE(server->at("version").text.empty());
  const std::optional<FlatJson> tracking = ParseFlatJson(tracking_line);
  ASSERT_TRUE(tracking.has_value()) << json.Describe();
  EXPECT_EQ(tracking->at("device").text, "cpu");
  EXPECT_EQ(tracking->at("kind").text, "cpu");
  EXPECT_EQ(tracking->at("name").text, "cpu (2 threads, interactive)");
  const std::optional<FlatJson> mapping = ParseFlatJson(mapping_line);
  ASSERT_TRUE(mapping.has_value()) << json.Describe();
  EXPECT_EQ(mapping->at("device").text, "cpu-mapping");
  EXPECT_EQ(mapping->at("name").text, "cpu (2 threads, mapping, nice +10)");
  EXPECT_EQ(daemon.Stop(), 0) << daemon.Log();
}

#else

TEST(RemoteCliTest, NeedsPlenoxd) {
  GTEST_SKIP() << "plenoxd is not built (PLX_WITH_SERVER=OFF)";
}

#endif  // PLENOXD_BINARY

}  // namespace remote_cli_test
}  // namespace plx

// Black-box tests of the `plenox` executable: exit codes, messages, files written (and not
// written), and an end-to-end synth -> map -> eval-map -> render run on a small synthetic
// sequence. Everything runs the real binary (PLENOX_BINARY) in scratch folders, the way a user
// or a script would.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "core/formats/map_file.h"
#include "tests/clients/cli_runner.h"
#include "tests/clients/depthless_dataset.h"
#include "tests/clients/mesh_output.h"
#include "tests/test_util.h"

namespace plx {
namespace plenox_cli_test {
using cli::kExitOk;
using cli::kExitFailure;
using cli::kExitUsage;

namespace fs = std::filesystem;
using plx::testing::CommandResult;
using plx::testing::CopyWithoutDepthAtStart;
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
using plx::testing::WriteStringToFile;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::Not;
using ::testing::StartsWith;


// Mapping is multithreaded; pinning the thread count keeps the numbers reproducible on machines
// with different core counts (and keeps the suite within the 2 cores CI has).
constexpr char kThreads[] = "2";

double Median(std::vector<double> values) {
  if (values.empty()) return std::nan("");
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// ---------------------------------------------------------------------------------------------
// Top-level usage.

TEST(PlenoxUsageTest, NoArgumentsPrintsUsageAndExits2) {
  const CommandResult r = RunPlenox({});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
  const std::string all = r.out + r.err;
  EXPECT_THAT(all, HasSubstr("usage: plenox <command>")) << r.Describe();
  for (const char* command : {"demo", "map", "slam", "eval-map", "render", "synth"}) {
    EXPECT_THAT(all, HasSubstr(std::string("  ") + command + " ")) << command;
  }
}

TEST(PlenoxUsageTest, HelpExits0) {
  for (const char* help : {"--help", "-h", "help"}) {
    const CommandResult r = RunPlenox({help});
    EXPECT_EQ(r.exit_code, kExitOk) << r.Describe();
    EXPECT_THAT(r.out, HasSubstr("usage: plenox <command>")) << r.Describe();
  }
}

TEST(PlenoxUsageTest, UnknownCommandExits2NamingIt) {
  const CommandResult r = RunPlenox({"bogus", "--out", "x"});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
  EXPECT_THAT(r.err, AllOf(HasSubstr("unknown command"), HasSubstr("\"bogus\""))) << r.Describe();
  EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
}

TEST(PlenoxUsageTest, EveryCommandHelpListsItsFlags) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> commands = {
      {"map",
       {"--dataset", "--format", "--intrinsics", "--depth-scale", "--out", "--every",
        "--voxel-size", "--time-budget", "--iterations", "--batch", "--max-depth", "--seed",
        "--backend", "--device", "--threads", "--json", "--quiet", "--help"}},
      {"eval-map",
       {"--map", "--dataset", "--format", "--intrinsics", "--depth-scale", "--every", "--frames",
        "--pixels", "--max-depth", "--backend", "--device", "--threads", "--json", "--help"}},
      {"render",
       {"--map", "--pose", "--intrinsics", "--color", "--depth", "--json", "--backend", "--device",
        "--threads", "--help"}},
      {"track",
       {"--map", "--dataset", "--out", "--mode", "--rays", "--iterations", "--pixels",
        "--backend", "--device", "--threads", "--json", "--quiet", "--help"}},
      {"slam",
       {"--dataset", "--out", "--corrected-out", "--map-out", "--keyframes-out", "--loops-out",
        "--realtime", "--speed", "--deterministic", "--max-frames", "--iterations-per-keyframe",
        "--kf-translation", "--kf-rotation", "--kf-unmapped", "--kf-interval",
        "--no-loop-closure", "--window", "--refine-window",
        "--mapping-nice", "--new-segment-after", "--mode", "--rays", "--iterations",
        "--pixels", "--voxel-size", "--backend",
        "--device", "--threads", "--json", "--quiet", "--help"}},
      {"synth",
       {"--out", "--frames", "--width", "--height", "--noise", "--noise-seed", "--help"}},
      {"export",
       {"--map", "--out", "--mesh", "--format", "--lod-triangles", "--bbox", "--min-density",
        "--iso-level", "--min-component", "--max-triangles", "--mesh-surface", "--keep-unobserved",
        "--mesh-color", "--backend", "--device", "--threads", "--json", "--quiet", "--help"}},
      {"demo",
       {"--out", "--frames", "--width", "--height", "--no-noise", "--noise-seed", "--voxel-size",
        "--iterations", "--seed", "--every", "--backend", "--device", "--threads", "--json",
        "--help"}},
  };
  for (const auto& [command, flags] : commands) {
    SCOPED_TRACE(command);
    // --help works without the command's required flags.
    const CommandResult r = RunPlenox({command, "--help"});
    EXPECT_EQ(r.exit_code, kExitOk) << r.Describe();
    EXPECT_THAT(r.out, StartsWith("usage: plenox " + command + " ")) << r.Describe();
    for (const std::string& flag : flags) {
      EXPECT_THAT(r.out, HasSubstr("\n  " + flag + " ")) << flag << "\n" << r.Describe();
    }
    EXPECT_THAT(r.err, IsEmpty());
  }
}

TEST(PlenoxUsageTest, HelpAfterOtherFlagsStillShowsHelp) {
  const CommandResult r = RunPlenox({"map", "--every", "3", "--help"});
  EXPECT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.out, StartsWith("usage: plenox map ")) << r.Describe();
}

TEST(PlenoxUsageTest, RequiredFlagsAreMarkedInHelp) {
  const CommandResult r = RunPlenox({"render", "--help"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  for (const char* flag : {"--map", "--pose", "--intrinsics"}) {
    const size_t at = r.out.find(std::string("\n  ") + flag + " ");
    ASSERT_NE(at, std::string::npos) << flag;
    EXPECT_THAT(r.out.substr(at, r.out.find('\n', at + 1) - at), HasSubstr("(required)")) << flag;
  }
}

// The demo combines the synthetic-sequence and mapper flags; each must appear once (FlagSet
// aborts on a redeclaration, so a clash would also fail here).
TEST(PlenoxUsageTest, DemoHelpListsEachFlagOnce) {
  const CommandResult r = RunPlenox({"demo", "--help"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  std::istringstream lines(r.out);
  std::multiset<std::string> names;
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("  --", 0) == 0) names.insert(line.substr(2, line.find(' ', 2) - 2));
  }
  for (const std::string& name : std::set<std::string>(names.begin(), names.end())) {
    EXPECT_EQ(names.count(name), 1u) << name << " is listed more than once\n" << r.out;
  }
}

// ---------------------------------------------------------------------------------------------
// Bad input. Every case runs in a fresh folder and must leave it (and the shared dataset and
// map) exactly as it was: a failed command that still writes a map or an image misleads the
// scripts that look for those files.

class PlenoxBadInputTest : public ::testing::Test {
 protected:
  // One tiny synthetic sequence and a one-iteration map of it, shared by the whole suite: the
  // error paths need real inputs so that only the one thing under test is wrong.
  static void SetUpTestSuite() {
    root_ = new std::string(plx::testing::MakeTempDir("plenox_cli_inputs"));
    dataset_ = new std::string(*root_ + "/dataset");
    map_ = new std::string(*root_ + "/tiny.plx");
    setup_synth_ = new CommandResult(RunPlenox(
        {"synth", "--out", *dataset_, "--frames", "12", "--width", "32", "--height", "24"}));
    setup_map_ = new CommandResult(
        RunPlenox({"map", "--dataset", *dataset_, "--out", *map_, "--iterations", "1",
                   "--voxel-size", "0.08", "--threads", kThreads, "--quiet"}));
  }
  static void TearDownTestSuite() {
    const ::testing::TestSuite* suite = ::testing::UnitTest::GetInstance()->current_test_suite();
    if (suite == nullptr || !suite->Failed()) {
      std::error_code ec;
      fs::remove_all(*root_, ec);
    }
    delete setup_map_;
    delete setup_synth_;
    delete map_;
    delete dataset_;
    delete root_;
  }

  void SetUp() override {
    ASSERT_EQ(setup_synth_->exit_code, kExitOk) << setup_synth_->Describe();
    ASSERT_EQ(setup_map_->exit_code, kExitOk) << setup_map_->Describe();
    ASSERT_TRUE(fs::is_regular_file(*map_));
  }

  // Runs plenox in `work` and checks that it fails with `exit_code`, says every one of
  // `needles` on stderr after the "plenox" prefix, prints nothing on stdout, and changes nothing
  // in `work` or in the shared inputs.
  static CommandResult ExpectFailsCleanly(const std::vector<std::string>& args, int exit_code,
                                          const std::vector<std::string>& needles,
                                          const ScopedTempDir& work) {
    const std::set<std::string> work_before = ListTree(work.path());
    const std::set<std::string> inputs_before = ListTree(*root_);
    const CommandResult r = RunPlenox(args, work.path());
    EXPECT_EQ(r.exit_code, exit_code) << r.Describe();
    EXPECT_THAT(r.err, StartsWith("plenox")) << r.Describe();
    for (const std::string& needle : needles) {
      EXPECT_THAT(r.err, HasSubstr(needle)) << r.Describe();
    }
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
    EXPECT_EQ(ListTree(work.path()), work_before) << "files appeared\n" << r.Describe();
    EXPECT_EQ(ListTree(*root_), inputs_before) << "inputs changed\n" << r.Describe();
    return r;
  }

  static std::string* root_;
  static std::string* dataset_;
  static std::string* map_;
  static CommandResult* setup_synth_;
  static CommandResult* setup_map_;
};

std::string* PlenoxBadInputTest::root_ = nullptr;
std::string* PlenoxBadInputTest::dataset_ = nullptr;
std::string* PlenoxBadInputTest::map_ = nullptr;
CommandResult* PlenoxBadInputTest::setup_synth_ = nullptr;
CommandResult* PlenoxBadInputTest::setup_map_ = nullptr;

// Pose and intrinsics that are valid for the tiny sequence (32x24).
constexpr char kGoodPose[] = "0 0 0 0 0 0 1";
constexpr char kGoodIntrinsics[] = "27.2 27.2 16 12 32 24";

// In-process export of the suite's map file: a mesh the tests' PLY reader reads, counts in the
// JSON line matching the file; a point cloud without --mesh.
TEST_F(PlenoxBadInputTest, ExportWritesAMeshOrPointsOfAMapFile) {
  ScopedTempDir work("plenox_export");
  const CommandResult r = RunPlenox({"export", "--map", *map_, "--out", "mesh.ply", "--mesh",
                                     "--keep-unobserved", "--threads", kThreads, "--json"},
                                    work.path());
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_EQ(ListTree(work.path()), (std::set<std::string>{"mesh.ply"}));
  EXPECT_GT(plx::testing::ExpectMeshFileMatchingJson(work / "mesh.ply", r).num_triangles(), 0);

  const CommandResult points =
      RunPlenox({"export", "--map", *map_, "--out", "points.ply", "--threads", kThreads},
                work.path());
  ASSERT_EQ(points.exit_code, kExitOk) << points.Describe();
  EXPECT_THAT(points.out, HasSubstr("points"));
  EXPECT_THAT(ReadFileToString(work / "points.ply"), Not(HasSubstr("element face")));
}

// --format glb (or an --out ending in .glb): binary glTF the tests' strict reader reads, counts
// in the JSON line matching it; --lod-triangles N: at most N triangles, in either format, the
// JSON saying how many the full mesh had.
TEST_F(PlenoxBadInputTest, ExportWritesGlbAndLevelsOfDetail) {
  ScopedTempDir work("plenox_export_glb");
  const CommandResult full = RunPlenox({"export", "--map", *map_, "--out", "mesh.glb", "--mesh",
                                        "--keep-unobserved", "--threads", kThreads, "--json"},
                                       work.path());
  ASSERT_EQ(full.exit_code, kExitOk) << full.Describe();
  const plx::testing::GlbFile glb =
      plx::testing::ExpectGlbFileMatchingJson(work / "mesh.glb", full);
  const int64_t triangles = glb.mesh.num_triangles();
  ASSERT_GT(triangles, 20);
  EXPECT_EQ(JsonNumber(LastLineJson(full), "full_faces").value_or(-1), triangles);

  // The same with --format glb and another name.
  const CommandResult named = RunPlenox({"export", "--map", *map_, "--out", "mesh.bin", "--mesh",
                                         "--format", "glb", "--keep-unobserved", "--threads",
                                         kThreads},
                                        work.path());
  ASSERT_EQ(named.exit_code, kExitOk) << named.Describe();
  EXPECT_EQ(ReadFileToString(work / "mesh.bin"), ReadFileToString(work / "mesh.glb"));
  EXPECT_THAT(named.out, HasSubstr("glTF"));

  const int64_t budget = triangles / 4;
  for (const char* out : {"lod.glb", "lod.ply"}) {
    SCOPED_TRACE(out);
    const CommandResult lod = RunPlenox(
        {"export", "--map", *map_, "--out", out, "--mesh", "--keep-unobserved", "--lod-triangles",
         std::to_string(budget), "--threads", kThreads, "--json"},
        work.path());
    ASSERT_EQ(lod.exit_code, kExitOk) << lod.Describe();
    const FlatJson json = LastLineJson(lod);
    EXPECT_LE(JsonNumber(json, "faces").value_or(1e9), budget) << lod.Describe();
    EXPECT_EQ(JsonNumber(json, "full_faces").value_or(-1), triangles) << lod.Describe();
    EXPECT_GT(JsonNumber(json, "lod_error_m").value_or(-1), 0.0) << lod.Describe();
    if (std::string(out) == "lod.glb") {
      EXPECT_LE(plx::testing::ExpectGlbFileMatchingJson(work / out, lod).mesh.num_triangles(),
                budget);
    } else {
      EXPECT_LE(plx::testing::ExpectMeshFileMatchingJson(work / out, lod).num_triangles(), budget);
    }
  }
  // Without --json: the summary names the level of detail.
  const CommandResult text = RunPlenox({"export", "--map", *map_, "--out", "small.glb", "--mesh",
                                        "--keep-unobserved", "--lod-triangles",
                                        std::to_string(budget), "--threads", kThreads},
                                       work.path());
  ASSERT_EQ(text.exit_code, kExitOk) << text.Describe();
  EXPECT_THAT(text.out, AllOf(HasSubstr("wrote small.glb"),
                              HasSubstr(absl::StrCat("a level of detail of ", triangles)),
                              HasSubstr("glTF")))
      << text.Describe();
}

TEST_F(PlenoxBadInputTest, ExportFormatAndLevelOfDetailMistakesAreUsageErrors) {
  ScopedTempDir work("plenox_export_glb_bad");
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.glb", "--format", "glb"}, kExitUsage,
                     {"--format glb applies to --mesh only"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.glb"}, kExitUsage,
                     {"x.glb", "add --mesh"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--lod-triangles", "100"},
                     kExitUsage, {"--lod-triangles applies to --mesh only"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--mesh", "--format", "glb"},
                     kExitUsage, {"--format glb", "x.ply"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.glb", "--mesh", "--format", "ply"},
                     kExitUsage, {"--format ply", "x.glb"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.obj", "--mesh", "--format", "obj"},
                     kExitUsage, {"--format", "ply or glb", "obj"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.glb", "--mesh", "--lod-triangles", "-1"},
      kExitUsage, {"--lod-triangles"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.glb", "--mesh", "--lod-triangles", "20000001"},
      kExitUsage, {"--lod-triangles"}, work);
}

// --bbox: the triangles of the voxels whose centres are in the box, within half a voxel of it,
// the file and the JSON naming the box; two boxes sharing a face split the full mesh.
TEST_F(PlenoxBadInputTest, ExportWritesTheMeshOfABox) {
  ScopedTempDir work("plenox_export_bbox");
  const CommandResult full = RunPlenox({"export", "--map", *map_, "--out", "full.glb", "--mesh",
                                        "--keep-unobserved", "--threads", kThreads, "--json"},
                                       work.path());
  ASSERT_EQ(full.exit_code, kExitOk) << full.Describe();
  const plx::testing::GlbFile whole =
      plx::testing::ExpectGlbFileMatchingJson(work / "full.glb", full);
  ASSERT_GT(whole.mesh.num_triangles(), 20);
  ASSERT_EQ(whole.position_min.size(), 3u);
  // Split the mesh's extent along x at its middle; the boxes reach a metre past it elsewhere.
  const double middle = 0.5 * (whole.position_min[0] + whole.position_max[0]);
  // Written exactly (17 digits), as the JSON's bbox is: the same text comes back.
  const auto box_text = [](double x0, double y0, double z0, double x1, double y1, double z1) {
    return absl::StrFormat("%.17g,%.17g,%.17g,%.17g,%.17g,%.17g", x0, y0, z0, x1, y1, z1);
  };
  const std::vector<double>& lo = whole.position_min;
  const std::vector<double>& hi = whole.position_max;
  const std::string lower = box_text(lo[0] - 1, lo[1] - 1, lo[2] - 1, middle, hi[1] + 1, hi[2] + 1);
  const std::string upper = box_text(middle, lo[1] - 1, lo[2] - 1, hi[0] + 1, hi[1] + 1, hi[2] + 1);
  int64_t split = 0;
  for (const auto& [out, box] : {std::pair<std::string, std::string>{"lower.glb", lower},
                                 std::pair<std::string, std::string>{"upper.ply", upper}}) {
    SCOPED_TRACE(out);
    const CommandResult r = RunPlenox({"export", "--map", *map_, "--out", out, "--mesh",
                                       "--keep-unobserved", "--bbox", box, "--threads", kThreads,
                                       "--json"},
                                      work.path());
    ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
    const FlatJson json = LastLineJson(r);
    ASSERT_TRUE(json.count("bbox")) << r.Describe();
    EXPECT_EQ(json.at("bbox").text, box);
    const plx::TriangleMesh mesh = out == "lower.glb"
                                  ? plx::testing::ExpectGlbFileMatchingJson(work / out, r).mesh
                                  : plx::testing::ExpectMeshFileMatchingJson(work / out, r);
    EXPECT_GT(mesh.num_triangles(), 0);
    EXPECT_LT(mesh.num_triangles(), whole.mesh.num_triangles());
    split += mesh.num_triangles();
    // The map's voxels are 8 cm: half a voxel past the shared face at most.
    for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
      const float x = mesh.positions[3 * v];
      EXPECT_TRUE(out == "lower.glb" ? x <= middle + 0.0401 : x >= middle - 0.0401) << x;
    }
  }
  EXPECT_EQ(split, whole.mesh.num_triangles());
  EXPECT_THAT(ReadFileToString(work / "upper.ply"),
              HasSubstr("\ncomment plenoxd region: "));

  const CommandResult text =
      RunPlenox({"export", "--map", *map_, "--out", "nothing.glb", "--mesh", "--bbox",
                 "50,50,50,51,51,51", "--threads", kThreads},
                work.path());
  ASSERT_EQ(text.exit_code, kExitOk) << text.Describe();
  EXPECT_THAT(text.out, AllOf(HasSubstr("0 triangles"),
                              HasSubstr("in the box [50, 50, 50] .. [51, 51, 51]")))
      << text.Describe();
}

TEST_F(PlenoxBadInputTest, ABoxThatIsNotSixNumbersOfAFiniteNonEmptyBoxIsAUsageError) {
  ScopedTempDir work("plenox_export_bbox_bad");
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--bbox", "0,0,0,1,1,1"},
                     kExitUsage, {"--bbox applies to --mesh only"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.glb", "--mesh", "--bbox", "0,0,0,1,1"},
                     kExitUsage, {"--bbox: expected six numbers", "0,0,0,1,1"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.glb", "--mesh", "--bbox", "0,0,0,1,x,1"},
      kExitUsage, {"--bbox: expected six numbers"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.glb", "--mesh", "--bbox", "0,0,2,1,1,1"},
      kExitUsage, {"--bbox: min must be below max", "not on z"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.glb", "--mesh", "--bbox", "0,nan,0,1,1,1"},
      kExitUsage, {"--bbox: coordinates must be finite"}, work);
}

TEST_F(PlenoxBadInputTest, ExportFlagsOfTheOtherFormatAreUsageErrors) {
  ScopedTempDir work("plenox_export_bad");
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--iso-level", "30"},
                     kExitUsage, {"--iso-level", "--mesh"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--mesh", "--min-density", "3"},
                     kExitUsage, {"--min-density"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--mesh", "--mesh-color", "red"},
                     kExitUsage, {"--mesh-color"}, work);
  ExpectFailsCleanly({"export", "--map", *map_, "--out", "x.ply", "--mesh-surface", "density"},
                     kExitUsage, {"--mesh-surface", "--mesh"}, work);
  ExpectFailsCleanly(
      {"export", "--map", *map_, "--out", "x.ply", "--mesh", "--mesh-surface", "seen"},
      kExitUsage, {"--mesh-surface", "observed"}, work);
  ExpectFailsCleanly({"export", "--map", "missing.plx", "--out", "x.ply", "--mesh"}, kExitFailure,
                     {"missing.plx"}, work);
}

TEST_F(PlenoxBadInputTest, MapWithoutDatasetIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--out", "x.plx"}, kExitUsage, {"--dataset", "required"}, work);
}

TEST_F(PlenoxBadInputTest, MapWithoutOutIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_}, kExitUsage, {"--out", "required"}, work);
}

TEST_F(PlenoxBadInputTest, MapUnknownFlagIsUsageErrorNamingIt) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "x.plx", "--evrey", "3"}, kExitUsage,
                     {"--evrey"}, work);
}

TEST_F(PlenoxBadInputTest, MapStrayArgumentIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "x.plx", "extra"}, kExitUsage,
                     {"\"extra\""}, work);
}

TEST_F(PlenoxBadInputTest, MapMissingDatasetNamesThePath) {
  ScopedTempDir work("plenox_cli_bad");
  const std::string missing = work / "no_such_dataset";
  ExpectFailsCleanly({"map", "--dataset", missing, "--out", "x.plx"}, kExitFailure,
                     {missing, "not found"}, work);
}

TEST_F(PlenoxBadInputTest, MapEveryZeroIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "x.plx", "--every", "0"}, kExitUsage,
                     {"--every", "got 0"}, work);
}

TEST_F(PlenoxBadInputTest, MapVoxelSizeNotANumberIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "x.plx", "--voxel-size", "abc"},
                     kExitUsage, {"--voxel-size", "\"abc\""}, work);
}

TEST_F(PlenoxBadInputTest, MapVoxelSizeOutOfRangeIsUsageError) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "x.plx", "--voxel-size", "0"},
                     kExitUsage, {"--voxel-size"}, work);
}

TEST_F(PlenoxBadInputTest, MapWithNoBudgetIsUsageError) {
  // Zero iterations and no time budget would optimise forever.
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly(
      {"map", "--dataset", *dataset_, "--out", "x.plx", "--iterations", "0", "--time-budget", "0"},
      kExitUsage, {"budget"}, work);
}

TEST_F(PlenoxBadInputTest, MapIntoMissingFolderNamesItAndLeavesNoTempFile) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"map", "--dataset", *dataset_, "--out", "no_dir/x.plx", "--iterations", "1",
                      "--voxel-size", "0.08", "--threads", kThreads, "--quiet"},
                     kExitFailure, {"no_dir", "does not exist"}, work);
}

TEST_F(PlenoxBadInputTest, CorruptGroundTruthLineNamesFileAndLine) {
  ScopedTempDir work("plenox_cli_bad");
  const std::string copy = work / "corrupt";
  fs::copy(*dataset_, copy, fs::copy_options::recursive);
  // Line 5 of the file is a pose line (lines 1-2 are comments); spoil its qy field.
  const std::string gt_path = copy + "/groundtruth.txt";
  std::istringstream in(ReadFileToString(gt_path));
  std::string text, line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (n == 5) {
      std::istringstream fields(line);
      std::vector<std::string> f;
      for (std::string x; fields >> x;) f.push_back(x);
      ASSERT_EQ(f.size(), 8u) << line;
      f[5] = "abc";
      line = JoinFields(f, 0, 8);
    }
    text += line + "\n";
  }
  WriteStringToFile(gt_path, text);

  ExpectFailsCleanly({"map", "--dataset", copy, "--out", "x.plx", "--iterations", "1",
                      "--voxel-size", "0.08", "--threads", kThreads},
                     kExitFailure, {"groundtruth.txt:5", "\"abc\""}, work);
  ExpectFailsCleanly({"eval-map", "--map", *map_, "--dataset", copy}, kExitFailure,
                     {"groundtruth.txt:5", "\"abc\""}, work);
}

TEST_F(PlenoxBadInputTest, TruncatedGroundTruthLineNamesFileAndLine) {
  ScopedTempDir work("plenox_cli_bad");
  const std::string copy = work / "short_line";
  fs::copy(*dataset_, copy, fs::copy_options::recursive);
  const std::string gt_path = copy + "/groundtruth.txt";
  WriteStringToFile(gt_path, ReadFileToString(gt_path) + "9.5 1 2\n");
  const std::string corrupted = ReadFileToString(gt_path);
  const int last_line = static_cast<int>(std::count(corrupted.begin(), corrupted.end(), '\n'));
  ExpectFailsCleanly({"map", "--dataset", copy, "--out", "x.plx", "--iterations", "1"},
                     kExitFailure, {"groundtruth.txt:" + std::to_string(last_line)}, work);
}

TEST_F(PlenoxBadInputTest, EvalMapMissingMapNamesIt) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"eval-map", "--map", "missing.plx", "--dataset", *dataset_}, kExitFailure,
                     {"missing.plx"}, work);
}

TEST_F(PlenoxBadInputTest, EvalMapOnATextFileSaysItIsNotAMap) {
  ScopedTempDir work("plenox_cli_bad");
  WriteStringToFile(work / "notes.plx", "these are my notes, not a map\n");
  ExpectFailsCleanly({"eval-map", "--map", "notes.plx", "--dataset", *dataset_}, kExitFailure,
                     {"notes.plx", "not a plenoxd map file"}, work);
}

TEST_F(PlenoxBadInputTest, EvalMapWithoutHeldOutFramesSaysSo) {
  // 12 frames mapped every 100th: no index satisfies i % 100 == 50.
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"eval-map", "--map", *map_, "--dataset", *dataset_, "--every", "100"},
                     kExitFailure, {"held out"}, work);
}

TEST_F(PlenoxBadInputTest, RenderRejectsMalformedPose) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"0 0 0 0 0 0", "7 numbers"},      // one number short
      {"0 0 0 0 0 0 1 1", "7 numbers"},  // one too many
      {"0 0 nan 0 0 0 1", "\"nan\""},    // NaN translation
      {"0 0 0 0 0 0 inf", "\"inf\""},    // infinite quaternion
      {"0 0 0 0 0 0 0", "quaternion is zero"},
      {"1 2 3 x 0 0 1", "\"x\""},
  };
  for (const auto& [pose, needle] : cases) {
    SCOPED_TRACE(pose);
    ScopedTempDir work("plenox_cli_bad");
    ExpectFailsCleanly({"render", "--map", *map_, "--pose", pose, "--intrinsics", kGoodIntrinsics,
                        "--color", "c.png", "--depth", "d.png"},
                       kExitUsage, {"pose", needle}, work);
  }
}

TEST_F(PlenoxBadInputTest, RenderRejectsMalformedIntrinsics) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"27.2 27.2 16 12 32", "6 numbers"},
      {"27.2 27.2 16 12 32 24 1", "6 numbers"},
      {"27.2 27.2 16 12 32 x", "width and height"},
      {"27.2 27.2 16 12 32.5 24", "width and height"},
      {"-27.2 27.2 16 12 32 24", "focal"},
      {"27.2 nan 16 12 32 24", "focal"},
      {"27.2 27.2 16 12 0 24", "image size"},
      {"27.2 27.2 16 12 100000 24", "image size"},
      {"27.2 27.2 16 q 32 24", "\"q\""},
  };
  for (const auto& [intrinsics, needle] : cases) {
    SCOPED_TRACE(intrinsics);
    ScopedTempDir work("plenox_cli_bad");
    ExpectFailsCleanly({"render", "--map", *map_, "--pose", kGoodPose, "--intrinsics", intrinsics,
                        "--color", "c.png", "--depth", "d.png"},
                       kExitUsage, {needle}, work);
  }
}

TEST_F(PlenoxBadInputTest, RenderNeedsColorOrDepth) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly(
      {"render", "--map", *map_, "--pose", kGoodPose, "--intrinsics", kGoodIntrinsics}, kExitUsage,
      {"--color", "--depth"}, work);
}

TEST_F(PlenoxBadInputTest, RenderOfATextFileSaysItIsNotAMap) {
  ScopedTempDir work("plenox_cli_bad");
  WriteStringToFile(work / "notes.plx", "not a map\n");
  ExpectFailsCleanly({"render", "--map", "notes.plx", "--pose", kGoodPose, "--intrinsics",
                      kGoodIntrinsics, "--color", "c.png", "--depth", "d.png"},
                     kExitFailure, {"notes.plx", "not a plenoxd map file"}, work);
}

// --format, --intrinsics and --depth-scale are checked with the other flags: malformed values
// are usage errors (exit 2), reported before any file is read.
TEST_F(PlenoxBadInputTest, MalformedDatasetFlagsAreUsageErrors) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--format", "bogus"}, "bogus"},
      {{"--intrinsics", "1 2 3"}, "6 numbers"},
      {{"--intrinsics", kGoodIntrinsics, "--depth-scale", "abc"}, "--depth-scale"},
  };
  for (const auto& [extra, needle] : cases) {
    SCOPED_TRACE(extra[1]);
    ScopedTempDir work("plenox_cli_bad");
    std::vector<std::string> map_args = {"map", "--dataset", *dataset_, "--out", "x.plx"};
    map_args.insert(map_args.end(), extra.begin(), extra.end());
    ExpectFailsCleanly(map_args, kExitUsage, {needle}, work);
    std::vector<std::string> eval_args = {"eval-map", "--map", *map_, "--dataset", *dataset_};
    eval_args.insert(eval_args.end(), extra.begin(), extra.end());
    ExpectFailsCleanly(eval_args, kExitUsage, {needle}, work);
  }
}

// SLAM refuses what it cannot run before any work, and writes nothing then.
TEST_F(PlenoxBadInputTest, SlamBadInputFailsBeforeWork) {
  ScopedTempDir work("plenox_cli_slam_bad");
  ExpectFailsCleanly({"slam", "--dataset", *dataset_, "--out", "t.txt", "--realtime",
                      "--deterministic"},
                     kExitUsage, {"--realtime", "--deterministic"}, work);
  // The default bound is ignored in lock-step; one asked for with it is a contradiction.
  ExpectFailsCleanly({"slam", "--dataset", *dataset_, "--out", "t.txt", "--deterministic",
                      "--max-pending-keyframes", "1"},
                     kExitUsage, {"--max-pending-keyframes", "--deterministic"}, work);
  ExpectFailsCleanly({"slam", "--dataset", *dataset_, "--out", "t.txt", "--kf-unmapped", "2"},
                     kExitUsage, {"--kf-unmapped"}, work);
  ExpectFailsCleanly({"slam", "--dataset", *dataset_, "--out", "missing/t.txt"}, kExitFailure,
                     {"missing"}, work);
  // Intrinsics for another image size than the frames'.
  ExpectFailsCleanly({"slam", "--dataset", *dataset_, "--out", "t.txt", "--intrinsics",
                      "27.2 27.2 20 15 40 30", "--quiet"},
                     kExitFailure, {"40x30"}, work);
}

TEST_F(PlenoxBadInputTest, SlamOnADatasetWithoutDepthSaysSo) {
  ScopedTempDir work("plenox_cli_slam_nodepth");
  const std::string copy = work.path() + "/nodepth";
  fs::copy(*dataset_, copy, fs::copy_options::recursive);
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(copy)) {
    if (e.path().parent_path().filename() == "depth") {
      cv::Mat zero = cv::imread(e.path().string(), cv::IMREAD_UNCHANGED);
      zero.setTo(0);
      ASSERT_TRUE(cv::imwrite(e.path().string(), zero));
    }
  }
  const CommandResult r =
      RunPlenox({"slam", "--dataset", copy, "--out", work.path() + "/t.txt"}, work.path());
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr("no valid depth")) << r.Describe();
  EXPECT_FALSE(fs::exists(work.path() + "/t.txt"));
}

// render writes both images to temporary names and renames them only when both succeeded, so a
// failed render leaves nothing behind, and the message names the unwritable path.
TEST_F(PlenoxBadInputTest, RenderWritesNothingWhenTheDepthPathIsUnwritable) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"render", "--map", *map_, "--pose", kGoodPose, "--intrinsics",
                      kGoodIntrinsics, "--color", "c.png", "--depth", "no_dir/d.png"},
                     kExitFailure, {"no_dir/d.png"}, work);
}

// A --frames/--every combination without a held-out frame is a usage error found before
// anything is generated or written.
TEST_F(PlenoxBadInputTest, DemoWithoutHeldOutFramesFailsBeforeWriting) {
  ScopedTempDir work("plenox_cli_bad");
  ExpectFailsCleanly({"demo", "--out", "demo_out", "--frames", "3", "--width", "32", "--height",
                      "24", "--iterations", "1", "--threads", kThreads},
                     kExitUsage, {"--frames", "--every"}, work);
}

// ---------------------------------------------------------------------------------------------
// End to end on a small synthetic sequence: synth -> map -> eval-map -> render.

constexpr int kFrames = 30;
constexpr int kWidth = 96;
constexpr int kHeight = 72;
constexpr int kEvery = 10;
constexpr int kIterations = 60;

class PlenoxEndToEndTest : public ::testing::Test {
 protected:
  // The sequence and its map are built once for the suite; each test then reads them.
  static void SetUpTestSuite() {
    root_ = new std::string(plx::testing::MakeTempDir("plenox_cli_e2e"));
    dataset_ = new std::string(*root_ + "/sequence");
    map_ = new std::string(*root_ + "/map.plx");
    synth_ = new CommandResult(
        RunPlenox({"synth", "--out", *dataset_, "--frames", std::to_string(kFrames), "--width",
                   std::to_string(kWidth), "--height", std::to_string(kHeight)}));
    map_run_ = new CommandResult(
        RunPlenox({"map", "--dataset", *dataset_, "--out", *map_, "--every", std::to_string(kEvery),
                   "--iterations", std::to_string(kIterations), "--voxel-size", "0.04", "--threads",
                   kThreads, "--json"},
                  "", /*timeout_s=*/120.0));
  }
  static void TearDownTestSuite() {
    const ::testing::TestSuite* suite = ::testing::UnitTest::GetInstance()->current_test_suite();
    if (suite == nullptr || !suite->Failed()) {
      std::error_code ec;
      fs::remove_all(*root_, ec);
    }
    delete map_run_;
    delete synth_;
    delete map_;
    delete dataset_;
    delete root_;
  }

  void SetUp() override {
    ASSERT_EQ(synth_->exit_code, kExitOk) << synth_->Describe();
    ASSERT_EQ(map_run_->exit_code, kExitOk) << map_run_->Describe();
  }

  // eval-map of `map` on the held-out frames, every pixel, as parsed JSON.
  static FlatJson EvalMap(const std::string& map) {
    const CommandResult r =
        RunPlenox({"eval-map", "--map", map, "--dataset", *dataset_, "--every",
                   std::to_string(kEvery), "--pixels", "0", "--threads", kThreads, "--json"},
                  "", /*timeout_s=*/120.0);
    EXPECT_EQ(r.exit_code, kExitOk) << r.Describe();
    return LastLineJson(r);
  }

  static std::string* root_;
  static std::string* dataset_;
  static std::string* map_;
  static CommandResult* synth_;
  static CommandResult* map_run_;
};

std::string* PlenoxEndToEndTest::root_ = nullptr;
std::string* PlenoxEndToEndTest::dataset_ = nullptr;
std::string* PlenoxEndToEndTest::map_ = nullptr;
CommandResult* PlenoxEndToEndTest::synth_ = nullptr;
CommandResult* PlenoxEndToEndTest::map_run_ = nullptr;

TEST_F(PlenoxEndToEndTest, SynthWritesATumDataset) {
  EXPECT_THAT(synth_->out, HasSubstr(std::to_string(kFrames) + " frames")) << synth_->Describe();
  for (const char* name : {"rgb.txt", "depth.txt", "groundtruth.txt", "intrinsics.txt"}) {
    EXPECT_TRUE(fs::is_regular_file(*dataset_ + "/" + name)) << name;
  }
  EXPECT_EQ(ReadRows(*dataset_ + "/groundtruth.txt").size(), static_cast<size_t>(kFrames));
  EXPECT_EQ(ReadRows(*dataset_ + "/associations.txt").size(), static_cast<size_t>(kFrames));
}

TEST_F(PlenoxEndToEndTest, MapPrintsJsonSummaryAndWritesTheMap) {
  const FlatJson json = LastLineJson(*map_run_);
  // Frames 0, 10, 20 of 30.
  EXPECT_EQ(JsonNumber(json, "keyframes"), 3.0) << map_run_->Describe();
  EXPECT_EQ(JsonNumber(json, "iterations"), static_cast<double>(kIterations));
  for (const char* key : {"seconds", "map_mb", "peak_rss_mb"}) {
    const std::optional<double> v = JsonNumber(json, key);
    ASSERT_TRUE(v.has_value()) << key << "\n" << map_run_->Describe();
    EXPECT_GT(*v, 0.0) << key;
  }
  // The peak RSS has to hold at least the map itself.
  EXPECT_GE(JsonNumber(json, "peak_rss_mb").value_or(0), JsonNumber(json, "map_mb").value_or(1));
  ASSERT_TRUE(json.count("map"));
  EXPECT_TRUE(json.at("map").is_string);
  EXPECT_EQ(json.at("map").text, *map_);

  ASSERT_TRUE(fs::is_regular_file(*map_));
  // map_mb describes the map that was saved: the file holds the same payload, so the sizes
  // agree to within the small header and index overheads.
  const double file_mb = static_cast<double>(fs::file_size(*map_)) / 1e6;
  EXPECT_NEAR(JsonNumber(json, "map_mb").value_or(0), file_mb, 0.25 * file_mb);
  // No temp file from the atomic save survives.
  for (const auto& entry : fs::directory_iterator(*root_)) {
    EXPECT_THAT(entry.path().filename().string(), Not(HasSubstr(".tmp."))) << entry.path();
  }
}

TEST_F(PlenoxEndToEndTest, QuietMapPrintsNoProgressAndTextSummary) {
  // Without --json the summary is one human-readable line; --quiet silences stderr entirely.
  ScopedTempDir work("plenox_cli_e2e_quiet");
  const CommandResult r =
      RunPlenox({"map", "--dataset", *dataset_, "--out", "m.plx", "--iterations", "1",
                 "--voxel-size", "0.04", "--threads", kThreads, "--quiet"},
                work.path(), 120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.err, IsEmpty()) << r.Describe();
  EXPECT_THAT(r.out, AllOf(HasSubstr("wrote m.plx"), HasSubstr("3 keyframes"))) << r.Describe();
  EXPECT_TRUE(fs::is_regular_file(work / "m.plx"));
}

TEST_F(PlenoxEndToEndTest, JsonEscapesAwkwardMapNames) {
  // Scripts parse this line; a path with quotes, backslashes or spaces must not break it.
  ScopedTempDir work("plenox_cli_e2e_name");
  const std::string name = "my \"odd\\ map.plx";
  const CommandResult r =
      RunPlenox({"map", "--dataset", *dataset_, "--out", name, "--iterations", "1", "--voxel-size",
                 "0.04", "--threads", kThreads, "--quiet", "--json"},
                work.path(), 120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const FlatJson json = LastLineJson(r);
  ASSERT_TRUE(json.count("map")) << r.Describe();
  EXPECT_EQ(json.at("map").text, name);
  EXPECT_TRUE(fs::is_regular_file(work / name));
}

TEST_F(PlenoxEndToEndTest, EvalMapScoresHeldOutViews) {
  const FlatJson json = EvalMap(*map_);
  // Measured on this sequence: PSNR 31.5 dB, depth L1 1.8 cm, coverage 0.976. The bounds
  // leave room for tuning but not for a map that renders the wrong thing or nothing.
  EXPECT_GT(JsonNumber(json, "psnr").value_or(0), 27.0);
  EXPECT_LT(JsonNumber(json, "depth_l1_m").value_or(1e9), 0.04);
  EXPECT_LT(JsonNumber(json, "depth_l1_median_m").value_or(1e9), 0.04);
  EXPECT_GT(JsonNumber(json, "coverage").value_or(0), 0.9);
  EXPECT_LE(JsonNumber(json, "coverage").value_or(2), 1.0);
  // Frames 5, 15, 25, every pixel of each.
  EXPECT_EQ(JsonNumber(json, "frames"), 3.0);
  EXPECT_EQ(JsonNumber(json, "pixels"), static_cast<double>(3 * kWidth * kHeight));
}

TEST_F(PlenoxEndToEndTest, EvalMapTextOutputNamesTheMetrics) {
  const CommandResult r = RunPlenox(
      {"eval-map", "--map", *map_, "--dataset", *dataset_, "--frames", "1", "--threads", kThreads});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.out, AllOf(HasSubstr("held-out frames 1"), HasSubstr("PSNR"), HasSubstr("depth L1"),
                           HasSubstr("coverage")))
      << r.Describe();
}

TEST_F(PlenoxEndToEndTest, OptimisationImprovesOnASingleIteration) {
  // Depth fusion alone already gives a fair map, so absolute thresholds cannot tell whether
  // the optimiser did anything; comparing against a one-iteration map can.
  const std::string one_iteration = *root_ + "/one_iteration.plx";
  const CommandResult r = RunPlenox(
      {"map", "--dataset", *dataset_, "--out", one_iteration, "--every", std::to_string(kEvery),
       "--iterations", "1", "--voxel-size", "0.04", "--threads", kThreads, "--quiet"},
      "", 120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const FlatJson trained = EvalMap(*map_);
  const FlatJson initial = EvalMap(one_iteration);
  const double trained_psnr = JsonNumber(trained, "psnr").value_or(0);
  const double initial_psnr = JsonNumber(initial, "psnr").value_or(0);
  const double trained_l1 = JsonNumber(trained, "depth_l1_m").value_or(1e9);
  const double initial_l1 = JsonNumber(initial, "depth_l1_m").value_or(0);
  // Measured: 28.4 -> 31.5 dB and 3.4 -> 1.8 cm.
  EXPECT_GT(trained_psnr, initial_psnr + 1.0) << initial_psnr << " -> " << trained_psnr;
  EXPECT_LT(trained_l1, 0.8 * initial_l1) << initial_l1 << " -> " << trained_l1;
}

// track -> eval-traj on the synthetic sequence: every frame tracked, none lost, and the
// trajectory within a centimetre of the ground truth (measured 1.6 mm ATE at 96x72, 4 cm voxels).
TEST_F(PlenoxEndToEndTest, TrackWritesATrajectoryThatEvalTrajScores) {
  ScopedTempDir work("plenox_cli_track");
  const std::string trajectory = work.path() + "/traj.txt";
  const CommandResult r =
      RunPlenox({"track", "--map", *map_, "--dataset", *dataset_, "--out", trajectory, "--rays",
                 "1024", "--threads", kThreads, "--json"},
                "", /*timeout_s=*/120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  ASSERT_TRUE(json.has_value()) << r.Describe();
  EXPECT_EQ(JsonNumber(*json, "frames").value_or(-1), kFrames);
  EXPECT_EQ(JsonNumber(*json, "lost").value_or(-1), 0);
  EXPECT_GT(JsonNumber(*json, "ms_per_frame_median").value_or(-1), 0.0);
  EXPECT_GE(JsonNumber(*json, "ms_per_frame_p95").value_or(-1),
            JsonNumber(*json, "ms_per_frame_median").value_or(-1));
  ASSERT_TRUE(fs::exists(trajectory));

  const CommandResult scored = RunPlenox(
      {"eval-traj", "--est", trajectory, "--gt", *dataset_ + "/groundtruth.txt", "--json"});
  ASSERT_EQ(scored.exit_code, kExitOk) << scored.Describe();
  const std::optional<FlatJson> ate = ParseFlatJson(LastLine(scored.out));
  ASSERT_TRUE(ate.has_value()) << scored.Describe();
  EXPECT_EQ(JsonNumber(*ate, "matched").value_or(-1), kFrames);
  EXPECT_LT(JsonNumber(*ate, "ate_rmse_m").value_or(-1), 0.01);
}

TEST_F(PlenoxEndToEndTest, SlamWritesTrajectoryKeyframesAndMapAndScoresThem) {
  ScopedTempDir work("plenox_cli_slam");
  const std::string trajectory = work.path() + "/slam.txt";
  const std::string keyframes = work.path() + "/keyframes.txt";
  const std::string map = work.path() + "/slam.plx";
  const std::string corrected = work.path() + "/corrected.txt";
  const CommandResult r = RunPlenox(
      {"slam", "--dataset", *dataset_, "--out", trajectory, "--keyframes-out", keyframes,
       "--map-out", map, "--corrected-out", corrected, "--deterministic", "--voxel-size",
       "0.03", "--rays", "1024", "--iterations-per-keyframe", "20", "--json"},
      "", /*timeout_s=*/300.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr("started at frame 0's ground-truth pose")) << r.Describe();
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(JsonNumber(json, "frames"), kFrames);
  EXPECT_EQ(JsonNumber(json, "processed"), kFrames);
  EXPECT_EQ(JsonNumber(json, "lost").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "dropped").value_or(-1), 0);
  const double keyframe_count = JsonNumber(json, "keyframes").value_or(0);
  EXPECT_GE(keyframe_count, 2);
  EXPECT_LT(keyframe_count, kFrames);
  for (const char* key : {"ms_per_frame_median", "fps", "map_mb", "keyframe_mb", "peak_rss_mb",
                          "mapping_iterations"}) {
    EXPECT_GT(JsonNumber(json, key).value_or(0), 0.0) << key;
  }
  // Measured 1.3 cm SE(3) at this size (96x72, 3 cm voxels); the tracker in a map built from
  // ground-truth poses does about as well here.
  EXPECT_LT(JsonNumber(json, "ate_se3_m").value_or(1), 0.03) << r.Describe();
  EXPECT_EQ(ReadRows(trajectory).size(), static_cast<size_t>(kFrames));
  EXPECT_EQ(ReadRows(keyframes).size(), static_cast<size_t>(keyframe_count));
  // One arc of the room, no place seen twice: no loop, no correction; the trajectory in the
  // map's final frame (each pose on its keyframe as refined at the end) is scored as well.
  EXPECT_EQ(JsonNumber(json, "loops_accepted").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "corrections").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "corrections_in_place").value_or(-1), 0);
  EXPECT_EQ(ReadRows(corrected).size(), static_cast<size_t>(kFrames));
  EXPECT_LT(JsonNumber(json, "corrected_ate_se3_m").value_or(1), 0.03) << r.Describe();
  // The same ATE as eval-traj computes from the written file.
  const CommandResult scored =
      RunPlenox({"eval-traj", "--est", trajectory, "--gt", *dataset_ + "/groundtruth.txt",
                 "--align", "se3", "--json"});
  ASSERT_EQ(scored.exit_code, kExitOk) << scored.Describe();
  EXPECT_NEAR(JsonNumber(LastLineJson(scored), "ate_rmse_m").value_or(-1),
              JsonNumber(json, "ate_se3_m").value_or(-2), 1e-6);
  // The map is a map: eval-map reads it and it renders the held-out frames.
  const FlatJson eval = EvalMap(map);
  EXPECT_GT(JsonNumber(eval, "coverage").value_or(0), 0.8);
  // With its keyframes (format version 2), so plenoxd loading it can continue it.
  const absl::StatusOr<LoadedMapFile> file = LoadMapFile(map);
  ASSERT_TRUE(file.ok()) << file.status();
  ASSERT_EQ(static_cast<double>(file->state.keyframes.size()), keyframe_count);
  for (const MapKeyframe& k : file->state.keyframes) EXPECT_NE(k.features, nullptr);
}

// A sequence whose first frames have no depth (a depth camera starting up): they are WAITING,
// counted in the summary and the JSON; the first frame with depth starts the map and the rest
// track.
TEST_F(PlenoxEndToEndTest, SlamWaitsForAFrameWithDepthToStartTheMap) {
  constexpr int kEmpty = 3;
  constexpr int kRun = 12;
  ScopedTempDir work("plenox_cli_slam_waiting");
  const std::string copy = work.path() + "/late_depth";
  ASSERT_EQ(CopyWithoutDepthAtStart(*dataset_, copy, kEmpty), "");
  const std::string trajectory = work.path() + "/slam.txt";
  const CommandResult r = RunPlenox(
      {"slam", "--dataset", copy, "--out", trajectory, "--deterministic", "--voxel-size", "0.03",
       "--rays", "1024", "--iterations-per-keyframe", "20", "--max-frames", std::to_string(kRun),
       "--json"},
      "", /*timeout_s=*/300.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr(std::to_string(kEmpty) + " waiting")) << r.Describe();
  const FlatJson json = LastLineJson(r);
  EXPECT_EQ(JsonNumber(json, "processed").value_or(-1), kRun);
  EXPECT_EQ(JsonNumber(json, "waiting").value_or(-1), kEmpty);
  EXPECT_EQ(JsonNumber(json, "lost").value_or(-1), 0);
  EXPECT_EQ(JsonNumber(json, "ok").value_or(0) + JsonNumber(json, "degraded").value_or(0),
            kRun - kEmpty);
  EXPECT_GE(JsonNumber(json, "keyframes").value_or(0), 1);
  EXPECT_EQ(ReadRows(trajectory).size(), static_cast<size_t>(kRun));
}

TEST_F(PlenoxEndToEndTest, TrackRejectsBadFlagsBeforeWork) {
  ScopedTempDir work("plenox_cli_track_bad");
  for (const std::vector<std::string>& extra :
       {std::vector<std::string>{"--mode", "newton"}, std::vector<std::string>{"--rays", "3"},
        std::vector<std::string>{"--iterations", "0"},
        std::vector<std::string>{"--pixels", "random"}}) {
    std::vector<std::string> args = {"track", "--map", *map_, "--dataset", *dataset_, "--out",
                                     work.path() + "/t.txt"};
    args.insert(args.end(), extra.begin(), extra.end());
    const CommandResult r = RunPlenox(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_FALSE(fs::exists(work.path() + "/t.txt"));
  }
  const CommandResult missing = RunPlenox({"track", "--map", work.path() + "/none.plx", "--dataset",
                                           *dataset_, "--out", work.path() + "/t.txt"});
  EXPECT_EQ(missing.exit_code, kExitFailure) << missing.Describe();
  EXPECT_THAT(missing.err, HasSubstr("none.plx")) << missing.Describe();
}

TEST_F(PlenoxEndToEndTest, RenderMatchesTheSequenceAtAHeldOutFrame) {
  // Frame 15 was not mapped (keyframes 0, 10, 20), so this checks a novel view, and the pose
  // and intrinsics go through the same text the user would paste from the dataset files.
  constexpr int kFrame = 15;
  const auto intrinsics_rows = ReadRows(*dataset_ + "/intrinsics.txt");
  ASSERT_EQ(intrinsics_rows.size(), 1u);
  ASSERT_GE(intrinsics_rows[0].size(), 7u);
  const std::string intrinsics = JoinFields(intrinsics_rows[0], 0, 6);
  const double depth_scale = std::stod(intrinsics_rows[0][6]);
  const auto associations = ReadRows(*dataset_ + "/associations.txt");
  ASSERT_GT(associations.size(), static_cast<size_t>(kFrame));
  const std::vector<std::string>& frame = associations[kFrame];
  ASSERT_EQ(frame.size(), 4u);
  std::string pose;
  for (const auto& row : ReadRows(*dataset_ + "/groundtruth.txt")) {
    if (row.size() == 8 && row[0] == frame[0]) pose = JoinFields(row, 1, 7);
  }
  ASSERT_FALSE(pose.empty()) << "no ground truth at " << frame[0];

  ScopedTempDir work("plenox_cli_render");
  const CommandResult r =
      RunPlenox({"render", "--map", *map_, "--pose", pose, "--intrinsics", intrinsics, "--color",
                 "c.png", "--depth", "d.png", "--threads", kThreads},
                work.path());
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.out, AllOf(HasSubstr("c.png"), HasSubstr("d.png"))) << r.Describe();

  const cv::Mat color = cv::imread(work / "c.png", cv::IMREAD_UNCHANGED);
  const cv::Mat depth = cv::imread(work / "d.png", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(color.empty());
  ASSERT_FALSE(depth.empty());
  EXPECT_EQ(color.type(), CV_8UC3);
  EXPECT_EQ(depth.type(), CV_16UC1);
  EXPECT_EQ(color.cols, kWidth);
  EXPECT_EQ(color.rows, kHeight);
  ASSERT_EQ(depth.cols, kWidth);
  ASSERT_EQ(depth.rows, kHeight);

  const cv::Mat sensor_depth = cv::imread(*dataset_ + "/" + frame[3], cv::IMREAD_UNCHANGED);
  const cv::Mat sensor_color = cv::imread(*dataset_ + "/" + frame[1], cv::IMREAD_UNCHANGED);
  ASSERT_EQ(sensor_depth.type(), CV_16UC1);
  ASSERT_EQ(sensor_depth.size(), depth.size());
  ASSERT_EQ(sensor_color.type(), CV_8UC3);
  ASSERT_EQ(sensor_color.size(), color.size());

  // render writes millimetres; the dataset stores depth_scale units per metre.
  std::vector<double> rendered_m, sensor_m, abs_error_m;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const uint16_t rendered = depth.at<uint16_t>(v, u);
      const uint16_t sensor = sensor_depth.at<uint16_t>(v, u);
      if (rendered > 0) rendered_m.push_back(rendered / 1000.0);
      if (sensor > 0) sensor_m.push_back(sensor / depth_scale);
      if (rendered > 0 && sensor > 0) {
        abs_error_m.push_back(std::abs(rendered / 1000.0 - sensor / depth_scale));
      }
    }
  }
  // The map should cover nearly the whole view (eval-map coverage is ~0.97).
  EXPECT_GT(static_cast<double>(rendered_m.size()), 0.85 * kWidth * kHeight);
  EXPECT_NEAR(Median(rendered_m), Median(sensor_m), 0.03);
  // Per pixel too: a mirrored or mis-posed render can have the right median depth.
  EXPECT_LT(Median(abs_error_m), 0.03);

  // Colour: PSNR against the sensor image (eval-map measures ~31 dB on these frames).
  double squared_error = 0.0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      for (int c = 0; c < 3; ++c) {
        const double d = color.at<cv::Vec3b>(v, u)[c] - sensor_color.at<cv::Vec3b>(v, u)[c];
        squared_error += d * d;
      }
    }
  }
  const double mse = squared_error / (3.0 * kWidth * kHeight) / (255.0 * 255.0);
  EXPECT_GT(-10.0 * std::log10(std::max(mse, 1e-12)), 24.0);
}

// ---------------------------------------------------------------------------------------------
// The demo: the whole pipeline in one command.

TEST(PlenoxDemoTest, WritesSequenceMapRendersAndMetrics) {
  ScopedTempDir work("plenox_cli_demo");
  const std::string out = work / "demo_out";
  const CommandResult r =
      RunPlenox({"demo", "--out", out, "--frames", "30", "--width", "96", "--height", "72",
                 "--iterations", "40", "--threads", kThreads, "--json"},
                work.path(), 120.0);
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  // The human-readable summary says where everything went.
  EXPECT_THAT(r.out, HasSubstr(out)) << r.Describe();
  EXPECT_THAT(r.out, HasSubstr(out + "/map.plx")) << r.Describe();

  EXPECT_TRUE(fs::is_directory(out + "/sequence"));
  EXPECT_TRUE(fs::is_regular_file(out + "/sequence/groundtruth.txt"));
  EXPECT_TRUE(fs::is_regular_file(out + "/map.plx"));
  for (const char* png : {"heldout_render_color.png", "heldout_render_depth.png",
                          "heldout_sensor_color.png", "heldout_sensor_depth.png"}) {
    SCOPED_TRACE(png);
    const cv::Mat image = cv::imread(out + "/" + png, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.empty());
    EXPECT_EQ(image.cols, 96);
    EXPECT_EQ(image.rows, 72);
    EXPECT_EQ(image.type(),
              std::string(png).find("depth") != std::string::npos ? CV_16UC1 : CV_8UC3);
  }

  const FlatJson json = LastLineJson(r);
  // Measured: PSNR 30.1 dB, depth L1 2.2 cm, coverage 0.970 (with sensor-like depth noise).
  EXPECT_GT(JsonNumber(json, "psnr").value_or(0), 26.0) << r.Describe();
  EXPECT_LT(JsonNumber(json, "depth_l1_m").value_or(1e9), 0.05) << r.Describe();
  EXPECT_GT(JsonNumber(json, "coverage").value_or(0), 0.9) << r.Describe();
  EXPECT_EQ(JsonNumber(json, "frames"), 30.0);
  EXPECT_EQ(JsonNumber(json, "keyframes"), 3.0);
  EXPECT_EQ(JsonNumber(json, "heldout_frames"), 3.0);
  ASSERT_TRUE(json.count("map"));
  EXPECT_EQ(json.at("map").text, out + "/map.plx");
  // The last step: SLAM on the same frames without their poses.
  EXPECT_TRUE(fs::is_regular_file(out + "/slam_trajectory.txt"));
  EXPECT_EQ(ReadRows(out + "/slam_trajectory.txt").size(), 30u);
  EXPECT_EQ(JsonNumber(json, "slam_lost").value_or(-1), 0.0) << r.Describe();
  EXPECT_GE(JsonNumber(json, "slam_keyframes").value_or(0), 2.0);
  EXPECT_LT(JsonNumber(json, "slam_ate_rmse_m").value_or(1), 0.03) << r.Describe();
}

// ---------------------------------------------------------------------------------------------
// The helpers above decide what the tests see, so they get a few checks of their own.

TEST(CliRunnerTest, ParsesTheFlatJsonTheCliPrints) {
  const std::optional<FlatJson> json =
      ParseFlatJson(R"({"map": "a \"b\".plx", "keyframes": 3, "psnr": 31.5, "x": null})");
  ASSERT_TRUE(json.has_value());
  EXPECT_EQ(json->at("map").text, "a \"b\".plx");
  EXPECT_TRUE(json->at("map").is_string);
  EXPECT_EQ(JsonNumber(*json, "keyframes"), 3.0);
  EXPECT_EQ(JsonNumber(*json, "psnr"), 31.5);
  EXPECT_EQ(JsonNumber(*json, "x"), std::nullopt);    // null is not a number
  EXPECT_EQ(JsonNumber(*json, "map"), std::nullopt);  // a string is not a number
  EXPECT_EQ(JsonNumber(*json, "absent"), std::nullopt);
  EXPECT_TRUE(ParseFlatJson("{}").has_value());
}

TEST(CliRunnerTest, RejectsMalformedJson) {
  for (const char* bad : {"", "{", "{\"a\": 1", "{\"a\" 1}", "{\"a\": 1,}", "{\"a\": 1} x",
                          "{\"a\": 1, \"a\": 2}", "{\"a\": [1]}", "{a: 1}", "progress 50%"}) {
    EXPECT_FALSE(ParseFlatJson(bad).has_value()) << bad;
  }
}

TEST(CliRunnerTest, LastLineSkipsTrailingNewlines) {
  EXPECT_EQ(LastLine("a\nb\n\n"), "b");
  EXPECT_EQ(LastLine("only"), "only");
  EXPECT_EQ(LastLine(""), "");
}

TEST(CliRunnerTest, CapturesStreamsExitCodeAndTimeout) {
  const CommandResult r =
      plx::testing::RunCommand("/bin/sh", {"-c", "echo out; echo err >&2; exit 3"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.out, "out\n");
  EXPECT_EQ(r.err, "err\n");
  EXPECT_FALSE(r.timed_out);

  const CommandResult slow = plx::testing::RunCommand("/bin/sh", {"-c", "sleep 30"}, "", 0.5);
  EXPECT_TRUE(slow.timed_out);
  EXPECT_TRUE(slow.signaled);
  EXPECT_LT(slow.seconds, 10.0);
}

}  // namespace plenox_cli_test
}  // namespace plx

// The compute-backend flags of the in-process plenox commands (--backend cpu|cuda|auto,
// --device N, --threads N): help text, usage errors, the clear failure of --backend cuda where
// there is no CUDA (this build or this machine), and auto running on the CPU there, which the
// summary line and the --json output say.
#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/make_backend.h"
#include "tests/clients/cli_runner.h"
#include "tests/test_util.h"

namespace plx {
namespace {

namespace fs = std::filesystem;
using plx::testing::CommandResult;
using plx::testing::FlatJson;
using plx::testing::JsonNumber;
using plx::testing::LastLine;
using plx::testing::LastLineJson;
using plx::testing::ListTree;
using plx::testing::ParseFlatJson;
using plx::testing::RunPlenox;
using plx::testing::ScopedTempDir;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::StartsWith;

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

// The commands that compute in-process, each with the flags it needs besides the backend ones
// ({DIR} is replaced by a scratch folder). None of them gets far enough to read its inputs when
// a backend flag is wrong.
struct ComputeCommand {
  std::string name;
  std::vector<std::string> args;
};
std::vector<ComputeCommand> ComputeCommands(const std::string& dir) {
  return {
      {"map", {"map", "--dataset", dir + "/no_dataset", "--out", dir + "/m.plx"}},
      {"track",
       {"track", "--map", dir + "/no.plx", "--dataset", dir + "/no_dataset", "--out",
        dir + "/t.txt"}},
      {"eval-map", {"eval-map", "--map", dir + "/no.plx", "--dataset", dir + "/no_dataset"}},
      {"render",
       {"render", "--map", dir + "/no.plx", "--pose", "0 0 0 0 0 0 1", "--intrinsics",
        "27.2 27.2 16 12 32 24", "--color", dir + "/c.png"}},
      {"demo", {"demo", "--out", dir + "/demo"}},
  };
}

std::vector<std::string> With(std::vector<std::string> args,
                              const std::vector<std::string>& extra) {
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

std::string JsonString(const FlatJson& json, const std::string& key) {
  const auto it = json.find(key);
  return it != json.end() && it->second.is_string ? it->second.text : "<missing>";
}

TEST(BackendFlagsTest, EveryComputeCommandDocumentsThem) {
  ScopedTempDir work("plenox_backend_help");
  for (const ComputeCommand& c : ComputeCommands(work.path())) {
    SCOPED_TRACE(c.name);
    const CommandResult r = RunPlenox({c.name, "--help"});
    EXPECT_EQ(r.exit_code, kExitOk) << r.Describe();
    EXPECT_THAT(r.out, AllOf(HasSubstr("--backend cpu|cuda|auto"), HasSubstr("[default: auto]"),
                             HasSubstr("--device N"), HasSubstr("CUDA device"),
                             HasSubstr("--threads N")))
        << r.Describe();
  }
}

TEST(BackendFlagsTest, UnknownBackendIsUsageErrorNamingIt) {
  ScopedTempDir work("plenox_backend_bogus");
  for (const ComputeCommand& c : ComputeCommands(work.path())) {
    SCOPED_TRACE(c.name);
    const CommandResult r = RunPlenox(With(c.args, {"--backend", "bogus"}));
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_THAT(r.err, AllOf(StartsWith("plenox " + c.name + ": "),
                             HasSubstr("--backend must be cpu, cuda or auto"),
                             HasSubstr("\"bogus\"")))
        << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  }
  EXPECT_THAT(ListTree(work.path()), IsEmpty());
}

TEST(BackendFlagsTest, BadDeviceIsUsageError) {
  ScopedTempDir work("plenox_backend_device");
  const std::vector<std::string> map = ComputeCommands(work.path())[0].args;
  const CommandResult negative = RunPlenox(With(map, {"--device", "-1"}));
  EXPECT_EQ(negative.exit_code, kExitUsage) << negative.Describe();
  EXPECT_THAT(negative.err, HasSubstr("--device")) << negative.Describe();
  const CommandResult with_cpu = RunPlenox(With(map, {"--backend", "cpu", "--device", "1"}));
  EXPECT_EQ(with_cpu.exit_code, kExitUsage) << with_cpu.Describe();
  EXPECT_THAT(with_cpu.err, HasSubstr("--device only applies with --backend cuda or auto"))
      << with_cpu.Describe();
  EXPECT_THAT(ListTree(work.path()), IsEmpty());
}

// Without CUDA (not built, or no device) --backend cuda fails at once, before any input is
// read or output written, with a message that names CUDA and the way out.
TEST(BackendFlagsTest, CudaWithoutAGpuFailsClearlyBeforeWork) {
  if (CudaDeviceCount() > 0) GTEST_SKIP() << "a CUDA device is visible: --backend cuda works here";
  ScopedTempDir work("plenox_backend_cuda");
  for (const ComputeCommand& c : ComputeCommands(work.path())) {
    SCOPED_TRACE(c.name);
    const CommandResult r = RunPlenox(With(c.args, {"--backend", "cuda"}));
    EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
    EXPECT_THAT(r.err, AllOf(StartsWith("plenox " + c.name + ": --backend cuda: "),
                             HasSubstr("CUDA"), HasSubstr("--backend cpu")))
        << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  }
  // Not even the demo's output folder.
  EXPECT_THAT(ListTree(work.path()), IsEmpty());
}

// auto (the default) on a tiny synthetic sequence: CPU here, and the outputs say so.
class BackendAutoTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new std::string(plx::testing::MakeTempDir("plenox_backend_auto"));
    const CommandResult synth = RunPlenox({"synth", "--out", *root_ + "/dataset", "--frames", "12",
                                           "--width", "32", "--height", "24"});
    synth_ok_ = synth.exit_code == kExitOk;
  }
  static void TearDownTestSuite() {
    const ::testing::TestSuite* suite = ::testing::UnitTest::GetInstance()->current_test_suite();
    if (suite == nullptr || !suite->Failed()) {
      std::error_code ec;
      fs::remove_all(*root_, ec);
    }
    delete root_;
  }
  void SetUp() override { ASSERT_TRUE(synth_ok_); }

  // What auto picks on this machine, as the JSON's "backend" says it.
  static bool ExpectCpu() { return CudaDeviceCount() == 0; }

  static std::string* root_;
  static bool synth_ok_;
};
std::string* BackendAutoTest::root_ = nullptr;
bool BackendAutoTest::synth_ok_ = false;

TEST_F(BackendAutoTest, MapEvalRenderAndTrackReportTheBackend) {
  const std::string dataset = *root_ + "/dataset", map = *root_ + "/auto.plx";
  // Default (no --backend) and explicit auto are the same thing.
  const CommandResult mapped =
      RunPlenox({"map", "--dataset", dataset, "--out", map, "--iterations", "2", "--voxel-size",
                 "0.08", "--threads", "2", "--json"});
  ASSERT_EQ(mapped.exit_code, kExitOk) << mapped.Describe();
  const FlatJson mj = LastLineJson(mapped);
  if (ExpectCpu()) {
    EXPECT_EQ(JsonString(mj, "backend"), "cpu") << mapped.Describe();
    EXPECT_EQ(JsonNumber(mj, "threads"), 2.0) << mapped.Describe();
    // The summary line on stderr names the backend too.
    EXPECT_THAT(mapped.err, HasSubstr("[cpu, 2 threads]")) << mapped.Describe();
  } else {
    EXPECT_THAT(JsonString(mj, "backend"), StartsWith("cuda")) << mapped.Describe();
  }

  const CommandResult evaluated = RunPlenox({"eval-map", "--map", map, "--dataset", dataset,
                                             "--backend", "auto", "--threads", "2", "--json"});
  ASSERT_EQ(evaluated.exit_code, kExitOk) << evaluated.Describe();
  if (ExpectCpu()) {
    EXPECT_EQ(JsonString(LastLineJson(evaluated), "backend"), "cpu") << evaluated.Describe();
  }

  const CommandResult rendered =
      RunPlenox({"render", "--map", map, "--pose", "0 0 0 0 0 0 1", "--intrinsics",
                 "27.2 27.2 16 12 32 24", "--depth", *root_ + "/d.png", "--backend", "auto",
                 "--threads", "2", "--json"});
  ASSERT_EQ(rendered.exit_code, kExitOk) << rendered.Describe();
  const FlatJson rj = LastLineJson(rendered);
  if (ExpectCpu()) {
    EXPECT_EQ(JsonString(rj, "backend"), "cpu") << rendered.Describe();
  }
  EXPECT_EQ(JsonNumber(rj, "width"), 32.0) << rendered.Describe();
  EXPECT_TRUE(fs::is_regular_file(*root_ + "/d.png"));

  const CommandResult tracked =
      RunPlenox({"track", "--map", map, "--dataset", dataset, "--out", *root_ + "/t.txt",
                 "--rays", "256", "--iterations", "2", "--threads", "2", "--json"});
  ASSERT_EQ(tracked.exit_code, kExitOk) << tracked.Describe();
  if (ExpectCpu()) {
    EXPECT_EQ(JsonString(LastLineJson(tracked), "backend"), "cpu") << tracked.Describe();
    EXPECT_THAT(tracked.err, HasSubstr("[cpu, 2 threads]")) << tracked.Describe();
  }
}

TEST_F(BackendAutoTest, ExplicitCpuRunsOnTheCpu) {
  const CommandResult mapped =
      RunPlenox({"map", "--dataset", *root_ + "/dataset", "--out", *root_ + "/cpu.plx",
                 "--iterations", "1", "--voxel-size", "0.08", "--backend", "cpu", "--threads",
                 "1", "--quiet", "--json"});
  ASSERT_EQ(mapped.exit_code, kExitOk) << mapped.Describe();
  const FlatJson json = LastLineJson(mapped);
  EXPECT_EQ(JsonString(json, "backend"), "cpu") << mapped.Describe();
  EXPECT_EQ(JsonNumber(json, "threads"), 1.0) << mapped.Describe();
}

}  // namespace
}  // namespace plx

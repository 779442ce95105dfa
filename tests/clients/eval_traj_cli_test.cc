// Black-box tests of `plenox eval-traj`: exit codes, the --json line, the readable summary,
// and file errors with file:line, on small trajectories written by the tests.
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "tests/clients/cli_runner.h"

namespace plx {
namespace eval_traj_cli_test {
using cli::kExitOk;
using cli::kExitFailure;
using cli::kExitUsage;

using plx::testing::CommandResult;
using plx::testing::FlatJson;
using plx::testing::JsonNumber;
using plx::testing::LastLine;
using plx::testing::ParseFlatJson;
using plx::testing::RunPlenox;
using plx::testing::ScopedTempDir;
using plx::testing::WriteStringToFile;
using ::testing::HasSubstr;
using ::testing::IsEmpty;


// A TUM trajectory along x at 1 m/s, 8 Hz (0.125 m steps, exact in binary so path sums reach
// 1 m exactly), `n` poses from t = 1000 s, shifted sideways (y) by `dy` and in time by `dt`.
// Identity orientation.
std::string Line(int n, double dy = 0.0, double dt = 0.0) {
  std::string text = "# timestamp tx ty tz qx qy qz qw\n";
  for (int k = 0; k < n; ++k) {
    absl::StrAppend(&text, absl::StrFormat("%.6f %.9g %.9g 1.5 0 0 0 1\n",
                                           1000.0 + 0.125 * k + dt, 0.125 * k, dy));
  }
  return text;
}

class EvalTrajCliTest : public ::testing::Test {
 protected:
  EvalTrajCliTest() : dir_("eval_traj_cli") {
    gt_ = dir_ / "groundtruth.txt";
    est_ = dir_ / "est.txt";
    // 81 poses = 10 m: RPE pairs (8, 16), ..., (72, 80).
    WriteStringToFile(gt_, Line(81));
    WriteStringToFile(est_, Line(81, 0.1));
  }

  ScopedTempDir dir_;
  std::string gt_, est_;
};

TEST_F(EvalTrajCliTest, JsonHasTheDocumentedKeys) {
  const CommandResult r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--json"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  // One line of JSON on stdout.
  EXPECT_EQ(r.out.find('\n'), r.out.size() - 1) << r.Describe();
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  ASSERT_TRUE(json.has_value()) << r.Describe();
  for (const char* key : {"ate_rmse_m", "ate_mean_m", "ate_max_m", "rpe_t_m", "rpe_r_deg",
                          "pairs", "matched", "align"}) {
    EXPECT_TRUE(json->count(key)) << key << "\n" << r.Describe();
  }
  // A constant 0.1 m offset without alignment: ATE 0.1, RPE 0.
  EXPECT_NEAR(JsonNumber(*json, "ate_rmse_m").value_or(-1), 0.1, 1e-6);
  EXPECT_NEAR(JsonNumber(*json, "ate_mean_m").value_or(-1), 0.1, 1e-6);
  EXPECT_NEAR(JsonNumber(*json, "ate_max_m").value_or(-1), 0.1, 1e-6);
  EXPECT_NEAR(JsonNumber(*json, "rpe_t_m").value_or(-1), 0.0, 1e-9);
  EXPECT_NEAR(JsonNumber(*json, "rpe_r_deg").value_or(-1), 0.0, 1e-9);
  EXPECT_EQ(JsonNumber(*json, "pairs"), 9.0);
  EXPECT_EQ(JsonNumber(*json, "matched"), 81.0);
  EXPECT_TRUE(json->at("align").is_string);
  EXPECT_EQ(json->at("align").text, "none");
}

TEST_F(EvalTrajCliTest, Se3AlignmentRemovesTheOffset) {
  const CommandResult r =
      RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--align", "se3", "--json"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  ASSERT_TRUE(json.has_value()) << r.Describe();
  EXPECT_NEAR(JsonNumber(*json, "ate_rmse_m").value_or(-1), 0.0, 1e-6);
  EXPECT_EQ(json->at("align").text, "se3");
}

TEST_F(EvalTrajCliTest, DenseGroundTruthIsAssociated) {
  // Ground truth at 100 Hz over the same 10 s, the estimate (8 Hz) offset by 3 ms in time.
  std::string dense = "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n";
  for (int k = 0; k <= 1000; ++k) {
    absl::StrAppend(&dense,
                    absl::StrFormat("%.4f %.4f 0 1.5 0 0 0 1\n", 1000.0 + 0.01 * k, 0.01 * k));
  }
  WriteStringToFile(gt_, dense);
  WriteStringToFile(est_, Line(81, 0.0, 0.003));
  const CommandResult r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--json"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  ASSERT_TRUE(json.has_value()) << r.Describe();
  EXPECT_EQ(JsonNumber(*json, "matched"), 81.0);
  // Even k: 0.125 k is on the 10 ms grid, the stamp 3 ms later meets that sample: error 0.
  // Odd k: 0.125 k is 5 ms past the grid, the stamp (+3 ms) meets the sample 5 ms after the
  // true time, 5 mm further along at 1 m/s. So the largest error is 5 mm.
  EXPECT_NEAR(JsonNumber(*json, "ate_max_m").value_or(1), 0.005, 1e-6);

  // With --max-dt 0.001 nothing is close enough: a failure, not a usage error.
  const CommandResult strict =
      RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--max-dt", "0.001"});
  EXPECT_EQ(strict.exit_code, kExitFailure) << strict.Describe();
  EXPECT_THAT(strict.err, HasSubstr("no estimated pose has a ground-truth pose"));
}

TEST_F(EvalTrajCliTest, ReadableSummary) {
  const CommandResult r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  EXPECT_THAT(r.out, HasSubstr("matched 81 of 81"));
  EXPECT_THAT(r.out, HasSubstr("ATE  rmse 0.1000 m"));
  EXPECT_THAT(r.out, HasSubstr("9 consecutive pairs"));
}

TEST_F(EvalTrajCliTest, ShortTrajectoryHasNullRpe) {
  WriteStringToFile(est_, Line(10, 0.1));  // 1.125 m: no RPE pair
  const CommandResult r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--json"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.Describe();
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  ASSERT_TRUE(json.has_value()) << r.Describe();
  EXPECT_EQ(json->at("rpe_t_m").text, "null");
  EXPECT_EQ(json->at("rpe_r_deg").text, "null");
  EXPECT_EQ(JsonNumber(*json, "pairs"), 0.0);
  EXPECT_EQ(JsonNumber(*json, "matched"), 10.0);

  const CommandResult text = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_});
  ASSERT_EQ(text.exit_code, kExitOk) << text.Describe();
  EXPECT_THAT(text.out, HasSubstr("no pose pairs"));
}

TEST_F(EvalTrajCliTest, UsageErrorsExitTwo) {
  const std::vector<std::vector<std::string>> cases = {
      {"eval-traj"},
      {"eval-traj", "--est", est_},
      {"eval-traj", "--gt", gt_},
      {"eval-traj", "--est", est_, "--gt", gt_, "--align", "affine"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--max-dt", "-1"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--max-dt", "soon"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--delta", "0"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--delta", "nan"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--rpe-path", "ref"},
      {"eval-traj", "--est", est_, "--gt", gt_, "--bogus"},
  };
  for (const auto& args : cases) {
    const CommandResult r = RunPlenox(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.Describe();
    EXPECT_THAT(r.err, HasSubstr("plenox eval-traj:")) << r.Describe();
    EXPECT_THAT(r.out, IsEmpty()) << r.Describe();
  }
}

TEST_F(EvalTrajCliTest, HelpAndTopLevelUsage) {
  const CommandResult help = RunPlenox({"eval-traj", "--help"});
  EXPECT_EQ(help.exit_code, kExitOk) << help.Describe();
  for (const char* flag : {"--est", "--gt", "--align", "--max-dt", "--delta", "--json"}) {
    EXPECT_THAT(help.out, HasSubstr(flag));
  }
  const CommandResult top = RunPlenox({"--help"});
  EXPECT_EQ(top.exit_code, kExitOk) << top.Describe();
  EXPECT_THAT(top.out, HasSubstr("eval-traj  compare an estimated trajectory with ground truth"));
}

TEST_F(EvalTrajCliTest, BadFilesExitOneWithFileAndLine) {
  WriteStringToFile(est_, "# header\n1000.0 0 0 1.5 0 0 0 1\n1000.125 0.125 0 1.5 0 0 1\n");
  CommandResult r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_, "--json"});
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr(est_ + ":3: expected 8 numbers")) << r.Describe();
  EXPECT_THAT(r.out, IsEmpty());

  WriteStringToFile(est_, Line(81));
  WriteStringToFile(gt_, "1000.0 0 0 1.5 0 0 0 0\n");
  r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_});
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr(gt_ + ":1: the quaternion")) << r.Describe();

  r = RunPlenox({"eval-traj", "--est", dir_ / "missing.txt", "--gt", gt_});
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr("missing.txt: file not found"));

  WriteStringToFile(gt_, "# only a comment\n");
  r = RunPlenox({"eval-traj", "--est", est_, "--gt", gt_});
  EXPECT_EQ(r.exit_code, kExitFailure) << r.Describe();
  EXPECT_THAT(r.err, HasSubstr("no poses"));
}

}  // namespace eval_traj_cli_test
}  // namespace plx

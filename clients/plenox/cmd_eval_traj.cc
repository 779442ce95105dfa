// plenox eval-traj: compare an estimated trajectory with ground truth (ATE, RPE) the way evo
// does (core/eval/trajectory_metrics.h has the details and where they come from).
#include <iostream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "core/eval/trajectory_metrics.h"
#include "core/formats/trajectory_file.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "eval-traj";

void PrintSummary(const TrajectoryEvalResult& r, const TrajectoryEvalOptions& options) {
  std::cout << absl::StrFormat(
      "matched %d of %d estimated poses to ground truth (%d poses) within %g s\n", r.matched,
      r.estimate_poses, r.ground_truth_poses, options.max_dt);
  if (r.alignment == TrajectoryAlignment::kNone) {
    std::cout << "alignment: none\n";
  } else {
    const Similarity3& a = r.ate.alignment;
    const double angle_deg =
        RotationAngle(SE3(Eigen::Matrix3d(a.rotation), Eigen::Vector3d::Zero())) * 180.0 / M_PI;
    std::cout << absl::StrFormat("alignment: %s (Umeyama: rotation %.3f deg, translation %.4f m",
                                 TrajectoryAlignmentName(r.alignment), angle_deg,
                                 a.translation.norm());
    if (r.alignment == TrajectoryAlignment::kSim3) {
      std::cout << absl::StrFormat(", scale %.6f", a.scale);
    }
    std::cout << ")\n";
  }
  const ErrorStatistics& ate = r.ate.translation_m;
  std::cout << absl::StrFormat(
      "ATE  rmse %.4f m  mean %.4f m  median %.4f m  max %.4f m  (%d poses)\n", ate.rmse, ate.mean,
      ate.median, ate.max, ate.count);
  const char* path_name =
      options.rpe_path == RpePathSource::kEstimate ? "estimate" : "ground truth";
  if (r.rpe.pairs.empty()) {
    std::cout << absl::StrFormat(
        "RPE  no pose pairs: the %s travels %.3f m over the matched poses, and pairs %g m apart "
        "need at least %g m of path\n",
        path_name, r.rpe.path_length_m, options.rpe_delta_m, 2 * options.rpe_delta_m);
  } else {
    std::cout << absl::StrFormat(
        "RPE  translation rmse %.4f m  rotation rmse %.4f deg  (%d consecutive pairs, delta %g m "
        "of path along the %s)\n",
        r.rpe.translation_m.rmse, r.rpe.rotation_deg.rmse, r.rpe.translation_m.count,
        options.rpe_delta_m, path_name);
  }
}

}  // namespace

int RunEvalTraj(const std::vector<std::string>& args) {
  FlagSet flags("plenox eval-traj",
                "Compares an estimated trajectory with ground truth, as evo_ape / evo_rpe do.\n"
                "Both files are TUM trajectories (\"timestamp tx ty tz qx qy qz qw\" per line,\n"
                "world_T_camera); a TUM groundtruth.txt works as it is. Each estimated pose is\n"
                "matched to the ground-truth pose with the nearest timestamp within --max-dt.\n"
                "ATE: RMSE/mean/median/max of the camera-centre error after --align.\n"
                "RPE: errors of the relative motion between consecutive poses --delta metres of\n"
                "path apart (evo's consecutive pairs, path measured along --rpe-path), RMSE of\n"
                "the translation (m) and rotation angle (deg).");
  flags.Add("est", "TRAJ", "estimated trajectory (TUM format)", std::nullopt, true)
      .Add("gt", "GT", "ground-truth trajectory (TUM format)", std::nullopt, true)
      .Add("align", "none|se3|sim3",
           "align the estimate to the ground truth first (Umeyama; se3 = evo -a, sim3 = -as)",
           "none")
      .Add("max-dt", "S", "largest timestamp difference for a match, seconds (evo: 0.01)", "0.02")
      .Add("delta", "M", "RPE pair distance, metres of travelled path", "1")
      .Add("rpe-path", "est|gt",
           "trajectory whose path picks the RPE pairs (evo uses the estimate)", "est")
      .AddSwitch("json", "print the result as one line of JSON");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  TrajectoryEvalOptions options;
  absl::StatusOr<TrajectoryAlignment> alignment =
      ParseTrajectoryAlignment(flags.GetString("align"));
  if (!alignment.ok()) return ReportError(kCommand, alignment.status(), true);
  options.alignment = *alignment;
  absl::StatusOr<RpePathSource> rpe_path = ParseRpePathSource(flags.GetString("rpe-path"));
  if (!rpe_path.ok()) return ReportError(kCommand, rpe_path.status(), true);
  options.rpe_path = *rpe_path;
  absl::StatusOr<double> max_dt = flags.GetDouble("max-dt", 0.0, 1e9);
  if (!max_dt.ok()) return ReportError(kCommand, max_dt.status(), true);
  options.max_dt = *max_dt;
  absl::StatusOr<double> delta = flags.GetDouble("delta", 0.0, 1e9);
  if (!delta.ok()) return ReportError(kCommand, delta.status(), true);
  if (*delta <= 0.0) {
    return ReportError(kCommand, absl::InvalidArgumentError("--delta must be greater than 0"),
                       true);
  }
  options.rpe_delta_m = *delta;

  absl::StatusOr<std::vector<StampedPose>> estimate = ReadTumTrajectory(flags.GetString("est"));
  if (!estimate.ok()) return ReportError(kCommand, estimate.status());
  absl::StatusOr<std::vector<StampedPose>> ground_truth = ReadTumTrajectory(flags.GetString("gt"));
  if (!ground_truth.ok()) return ReportError(kCommand, ground_truth.status());
  if (estimate->empty()) {
    return ReportError(kCommand, absl::InvalidArgumentError(absl::StrCat(
                                     flags.GetString("est"), ": no poses in the file")));
  }
  if (ground_truth->empty()) {
    return ReportError(kCommand, absl::InvalidArgumentError(absl::StrCat(
                                     flags.GetString("gt"), ": no poses in the file")));
  }

  absl::StatusOr<TrajectoryEvalResult> r = EvaluateTrajectory(*estimate, *ground_truth, options);
  if (!r.ok()) return ReportError(kCommand, r.status());

  if (flags.GetSwitch("json")) {
    // NaN (no RPE pairs) is written as null.
    JsonObject json;
    json.Add("ate_rmse_m", r->ate.translation_m.rmse)
        .Add("ate_mean_m", r->ate.translation_m.mean)
        .Add("ate_max_m", r->ate.translation_m.max)
        .Add("rpe_t_m", r->rpe.translation_m.rmse)
        .Add("rpe_r_deg", r->rpe.rotation_deg.rmse)
        .Add("pairs", static_cast<int>(r->rpe.pairs.size()))
        .Add("matched", r->matched)
        .Add("align", std::string(TrajectoryAlignmentName(r->alignment)))
        .Add("ate_median_m", r->ate.translation_m.median)
        .Add("est_poses", r->estimate_poses)
        .Add("gt_poses", r->ground_truth_poses)
        .Add("scale", r->ate.alignment.scale)
        .Add("delta_m", options.rpe_delta_m)
        .Add("rpe_path", std::string(RpePathSourceName(options.rpe_path)));
    std::cout << json.str() << "\n";
  } else {
    PrintSummary(*r, options);
  }
  return kExitOk;
}

}  // namespace plx::cli

// plenox slam: online SLAM over a dataset's frames (core/slam): each frame's pose while the map
// grows, no ground truth used except frame 0's pose as the start when the dataset has one.
#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/map_flags.h"
#include "clients/plenox/slam_output.h"
#include "core/common/status_macros.h"
#include "core/eval/trajectory_metrics.h"
#include "core/formats/map_file.h"
#include "core/formats/trajectory_file.h"
#include "core/slam/slam_dataset.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "slam";

void AddSlamFlags(FlagSet& flags) {
  const SlamOptions d = DefaultSlamOptions();
  flags.Add("out", "TRAJ.txt", "trajectory to write (TUM format, one pose per processed frame)",
            std::nullopt, true)
      .Add("map-out", "MAP.plx", "write the final map here", "")
      .Add("keyframes-out", "F", "write the keyframes' (refined) poses here (TUM format)", "")
      .AddSwitch("realtime",
                 "replay at the frames' timestamps; frames the tracker cannot keep up with are "
                 "dropped (latest wins), as from a live sensor")
      .Add("speed", "X", "realtime replay speed (2 = twice as fast as recorded)", "1")
      .AddSwitch("deterministic",
                 "map in lock-step after each keyframe (CPU mapping on one thread): "
                 "bit-identical results run to run")
      .Add("max-frames", "N", "only the first N frames (0 = all)", "0")
      .Add("iterations-per-keyframe", "N", "mapping iterations each keyframe adds to the budget",
           absl::StrCat(d.mapping.iterations_per_keyframe))
      .Add("kf-translation", "M", "keyframe when no keyframe is this close (metres)",
           absl::StrCat(d.keyframes.max_translation_m))
      .Add("kf-rotation", "DEG", "keyframe when no keyframe is turned less than this (degrees)",
           absl::StrCat(std::round(d.keyframes.max_rotation_rad * 180.0 / M_PI)))
      .Add("kf-unmapped", "F", "keyframe when this fraction of the view is not mapped",
           absl::StrCat(d.keyframes.max_unmapped_fraction))
      .Add("kf-interval", "S", "keyframe when this long passed since the last one (0 = never)",
           absl::StrCat(d.keyframes.max_interval_s))
      .Add("window", "N", "mapping window: half of each batch from the last N keyframes",
           absl::StrCat(d.mapping.mapper.window_keyframes))
      .Add("refine-window", "N",
           "re-align the last N keyframes' poses to the map after each keyframe (0 = off)",
           absl::StrCat(d.refinement.window))
      .Add("mapping-nice", "N", "priority of the mapping thread below tracking (0-19)",
           absl::StrCat(d.mapping_nice))
      .Add("rpe-delta", "M", "RPE pair distance in metres of path (as eval-traj --delta)", "1");
}

absl::StatusOr<SlamDatasetOptions> OptionsFromFlags(const FlagSet& flags) {
  SlamDatasetOptions o;
  SlamOptions& s = o.slam;
  PLX_ASSIGN_OR_RETURN(const TrackerOptions tracker, TrackerOptionsFromFlags(flags));
  double voxel = 0.0;
  PLX_ASSIGN_OR_RETURN(voxel, VoxelSizeFromFlags(flags));
  s = SlamOptionsFor(static_cast<float>(voxel), tracker);
  PLX_ASSIGN_OR_RETURN(s.mapping.mapper.window_keyframes, flags.GetInt("window", 0, 1000));
  PLX_ASSIGN_OR_RETURN(s.mapping.iterations_per_keyframe,
                       flags.GetInt("iterations-per-keyframe", 1, kMaxIterationsPerKeyframe));
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_translation_m, flags.GetDouble("kf-translation", 1e-4, 100));
  double degrees = 0.0;
  PLX_ASSIGN_OR_RETURN(degrees, flags.GetDouble("kf-rotation", 0.01, 180));
  s.keyframes.max_rotation_rad = degrees * M_PI / 180.0;
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_unmapped_fraction, flags.GetDouble("kf-unmapped", 0.001, 1));
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_interval_s, flags.GetDouble("kf-interval", 0, 3600));
  PLX_ASSIGN_OR_RETURN(s.refinement.window, flags.GetInt("refine-window", 0, 1000));
  s.deterministic = flags.GetSwitch("deterministic");
  PLX_ASSIGN_OR_RETURN(s.mapping_nice, flags.GetInt("mapping-nice", 0, 19));
  o.realtime = flags.GetSwitch("realtime");
  PLX_ASSIGN_OR_RETURN(o.speed, flags.GetDouble("speed", 0.01, 100));
  PLX_ASSIGN_OR_RETURN(o.max_frames, flags.GetInt("max-frames", 0, 1 << 30));
  if (o.realtime && s.deterministic) {
    return absl::InvalidArgumentError("--realtime and --deterministic exclude each other");
  }
  PLX_RETURN_IF_ERROR(ValidateSlamOptions(s));
  return o;
}

// ATE (no alignment and SE(3)) and RPE of the trajectory against the dataset's ground truth,
// as eval-traj computes them; nothing when the dataset has none.
void Score(const RgbdDataset& dataset, const std::vector<StampedPose>& trajectory, double delta,
           SlamReport* report) {
  std::vector<StampedPose> gt;
  for (int i = 0; i < dataset.size(); ++i) {
    if (std::optional<SE3> pose = dataset.ground_truth(i)) gt.push_back({dataset.timestamp(i), *pose});
  }
  if (gt.size() < 3) return;
  TrajectoryEvalOptions options;
  options.rpe_delta_m = delta;
  absl::StatusOr<TrajectoryEvalResult> none = EvaluateTrajectory(trajectory, gt, options);
  options.alignment = TrajectoryAlignment::kSE3;
  absl::StatusOr<TrajectoryEvalResult> se3 = EvaluateTrajectory(trajectory, gt, options);
  if (!none.ok() || !se3.ok()) return;
  report->ate_none_m = none->ate.translation_m.rmse;
  report->ate_se3_m = se3->ate.translation_m.rmse;
  if (!se3->rpe.pairs.empty()) {
    report->rpe_m = se3->rpe.translation_m.rmse;
    report->rpe_deg = se3->rpe.rotation_deg.rmse;
  }
}

}  // namespace

int RunSlam(const std::vector<std::string>& args) {
  FlagSet flags("plenox slam",
                "Online RGB-D SLAM: tracks every frame of a dataset while the map grows from\n"
                "keyframes, and writes the trajectory in TUM format (timestamp tx ty tz qx qy qz\n"
                "qw, camera-to-world). No ground truth is used, except frame 0's pose as the\n"
                "start when the dataset has one (the trajectory is then in the ground-truth\n"
                "frame and is scored against it); otherwise it starts at the identity. Frames\n"
                "that cannot be tracked are LOST (the prediction is written), never mapped; the\n"
                "session relocalises after them.");
  AddDatasetFlags(flags);
  AddSlamFlags(flags);
  AddTrackerFlags(flags);
  AddVoxelSizeFlag(flags, "voxel size of the map");
  AddBackendFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<SlamDatasetOptions> options = OptionsFromFlags(flags);
  if (!options.ok()) return ReportError(kCommand, options.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  absl::StatusOr<double> rpe_delta = flags.GetDouble("rpe-delta", 1e-3, 1e6);
  if (!rpe_delta.ok()) return ReportError(kCommand, rpe_delta.status(), true);
  SlamReport report;
  report.trajectory = flags.GetString("out");
  for (const std::string& path :
       {report.trajectory, flags.GetString("map-out"), flags.GetString("keyframes-out")}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError(kCommand, s);
  }
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport(kCommand, flags, &exit_code);
  if (!backend) return exit_code;
  const SlamSession::BackendFactory mapping_backend =
      MappingBackendFactory(flags, options->slam.deterministic);
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport(kCommand, flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  if (dataset->size() > 0) {
    // A dataset without depth cannot be mapped: say so before any work.
    absl::StatusOr<RgbdFrame> first = dataset->LoadFrame(0);
    if (!first.ok()) return ReportError(kCommand, first.status());
    bool any_depth = false;
    for (float d : first->depth.data) any_depth = any_depth || d > 0.0f;
    if (!any_depth) {
      return ReportError(kCommand, absl::InvalidArgumentError(absl::StrCat(
                                       "frame 0 of ", dataset->name(),
                                       " has no valid depth: SLAM needs RGB-D frames")));
    }
  }

  ProgressLine line(!flags.GetSwitch("quiet"));
  int lost = 0;
  const int frames =
      options->max_frames > 0 ? std::min(options->max_frames, dataset->size()) : dataset->size();
  absl::StatusOr<SlamDatasetResult> result = RunSlamOnDataset(
      *dataset, *backend, mapping_backend, *options, [&](const SlamFrameResult& r) {
        lost += r.state == SlamState::kLost;
        line.Update(SlamProgressText(r.frame + 1, frames, SlamStateName(r.state), r.milliseconds,
                                     r.keyframes, lost, r.state == SlamState::kOk ? "" : r.reason));
        return true;
      });
  if (!result.ok()) return ReportError(kCommand, result.status());
  const std::string header =
      absl::StrCat("plenox slam: ", dataset->name(),
                   result->started_from_ground_truth ? " (started at frame 0's ground truth)"
                                                     : " (started at the identity)");
  if (absl::Status s = WriteTumTrajectory(report.trajectory, result->trajectory, header); !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (!flags.GetString("keyframes-out").empty()) {
    if (absl::Status s = WriteTumTrajectory(flags.GetString("keyframes-out"), result->keyframes,
                                            absl::StrCat(header, ", keyframes"));
        !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  if (!flags.GetString("map-out").empty() && result->map != nullptr) {
    if (absl::Status s = SaveMap(*result->map, flags.GetString("map-out")); !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  const SlamProgress& p = result->progress;
  report.frames = result->frames;
  report.processed = static_cast<int>(result->trajectory.size());
  report.dropped = result->dropped;
  report.keyframes = p.keyframes;
  report.ok = p.ok;
  report.degraded = p.degraded;
  report.lost = p.lost;
  report.relocalised = p.relocalised;
  report.ms_per_frame_median = result->ms_per_frame_median;
  report.ms_per_frame_p95 = result->ms_per_frame_p95;
  report.wall_s = result->wall_s;
  report.mapping_iterations = p.mapping_iterations;
  report.map_mb = p.map_bytes / 1e6;
  report.keyframe_mb = p.keyframe_bytes / 1e6;
  report.peak_rss_mb = PeakRssMb();
  report.started_from_ground_truth = result->started_from_ground_truth;
  Score(*dataset, result->trajectory, *rpe_delta, &report);
  line.Finish(SlamSummaryText(report, absl::StrCat(" [", BackendText(*backend), "]")));
  PrintSlamResult(report, flags.GetSwitch("json"),
                  JsonObject()
                      .Add("backend", backend->name())
                      .AddBool("deterministic", options->slam.deterministic)
                      .AddBool("realtime", options->realtime));
  return kExitOk;
}

}  // namespace plx::cli

#include "clients/plenox/slam_output.h"

#include <algorithm>
#include <cmath>
#include <iostream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/map_flags.h"
#include "core/common/status_macros.h"
#include "core/eval/trajectory_metrics.h"
#include "core/mapping/mapping_session.h"

namespace plx::cli {

void AddSlamFlags(FlagSet& flags, const std::string& voxel_help) {
  const SlamOptions d = DefaultSlamOptions();
  flags.Add("out", "TRAJ.txt", "trajectory to write (TUM format, one pose per processed frame)",
            std::nullopt, true)
      .Add("corrected-out", "TRAJ.txt",
           "also write the trajectory in the map's final frame: each pose moved with its "
           "keyframe by the loop closures' corrections (TUM format)",
           "")
      .AddSwitch("realtime",
                 "replay at the frames' timestamps; frames the tracker cannot keep up with are "
                 "dropped (latest wins), as from a live sensor, and no frame waits for mapping "
                 "(a keyframe stays deferred while mapping is behind)")
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
      .Add("max-pending-keyframes", "N",
           absl::StrCat("keyframes left waiting for mapping while tracking goes on (0-",
                        kMaxPendingKeyframes,
                        "; a keyframe beyond them is deferred): 0 = a keyframe's frame waits "
                        "for its integration; ignored with --deterministic"),
           absl::StrCat(d.max_pending_keyframes))
      .AddSwitch("no-loop-closure",
                 "no loop closure: keyframes keep the poses tracking gave them (docs/SLAM.md)")
      .Add("rpe-delta", "M", "RPE pair distance in metres of path (as eval-traj --delta)", "1");
  AddTrackerFlags(flags);
  AddVoxelSizeFlag(flags, voxel_help);
}

absl::StatusOr<SlamDatasetOptions> SlamOptionsFromFlags(const FlagSet& flags) {
  SlamDatasetOptions o;
  SlamOptions& s = o.slam;
  PLX_ASSIGN_OR_RETURN(const TrackerOptions tracker, TrackerOptionsFromFlags(flags));
  double voxel = 0.0;
  PLX_ASSIGN_OR_RETURN(voxel, VoxelSizeFromFlags(flags));
  // The daemon starts from the same SlamOptionsFor, so both forms run the same defaults.
  s = SlamOptionsFor(static_cast<float>(voxel), tracker);
  PLX_ASSIGN_OR_RETURN(s.mapping.iterations_per_keyframe,
                       flags.GetInt("iterations-per-keyframe", 1, kMaxIterationsPerKeyframe));
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_translation_m, flags.GetDouble("kf-translation", 1e-4, 100));
  double degrees = 0.0;
  PLX_ASSIGN_OR_RETURN(degrees, flags.GetDouble("kf-rotation", 0.01, 180));
  s.keyframes.max_rotation_rad = degrees * M_PI / 180.0;
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_unmapped_fraction, flags.GetDouble("kf-unmapped", 0.001, 1));
  PLX_ASSIGN_OR_RETURN(s.keyframes.max_interval_s, flags.GetDouble("kf-interval", 0, 3600));
  s.deterministic = flags.GetSwitch("deterministic");
  s.loop_closure.enabled = !flags.GetSwitch("no-loop-closure");
  PLX_ASSIGN_OR_RETURN(s.max_pending_keyframes,
                       flags.GetInt("max-pending-keyframes", 0, kMaxPendingKeyframes));
  if (s.deterministic && flags.IsSet("max-pending-keyframes") && s.max_pending_keyframes > 0) {
    return absl::InvalidArgumentError(
        "--max-pending-keyframes must be 0 with --deterministic (lock-step waits for each "
        "keyframe's mapping)");
  }
  o.realtime = flags.GetSwitch("realtime");
  PLX_ASSIGN_OR_RETURN(o.speed, flags.GetDouble("speed", 0.01, 100));
  PLX_ASSIGN_OR_RETURN(o.max_frames, flags.GetInt("max-frames", 0, 1 << 30));
  if (o.realtime && s.deterministic) {
    return absl::InvalidArgumentError("--realtime and --deterministic exclude each other");
  }
  PLX_RETURN_IF_ERROR(ValidateSlamOptions(s));
  return o;
}

absl::StatusOr<double> RpeDeltaFromFlags(const FlagSet& flags) {
  return flags.GetDouble("rpe-delta", 1e-3, 1e6);
}

absl::Status CheckSlamDataset(const RgbdDataset& dataset) {
  if (dataset.size() == 0) {
    return absl::InvalidArgumentError(absl::StrCat(dataset.name(), " has no frames"));
  }
  // A sequence may start without depth (a depth camera's first frames): SLAM waits for a frame
  // with enough to start the map (SlamState::kWaiting), so any frame with depth will do here.
  for (int i = 0; i < dataset.size(); ++i) {
    PLX_ASSIGN_OR_RETURN(const RgbdFrame frame, dataset.LoadFrame(i));
    if (std::any_of(frame.depth.data.begin(), frame.depth.data.end(),
                    [](float d) { return d > 0.0f; })) {
      return absl::OkStatus();
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat(dataset.name(), " has no valid depth in any of its ", dataset.size(),
                   " frames: SLAM needs RGB-D frames"));
}

int SlamFrameCount(const RgbdDataset& dataset, const SlamDatasetOptions& options) {
  return options.max_frames > 0 ? std::min(options.max_frames, dataset.size()) : dataset.size();
}

void ScoreSlamTrajectory(const RgbdDataset& dataset, const std::vector<StampedPose>& trajectory,
                         const std::vector<StampedPose>& corrected, double rpe_delta_m,
                         SlamReport* report) {
  std::vector<StampedPose> gt;
  for (int i = 0; i < dataset.size(); ++i) {
    if (std::optional<SE3> pose = dataset.ground_truth(i)) {
      gt.push_back({dataset.timestamp(i), *pose});
    }
  }
  if (gt.size() < 3) return;
  TrajectoryEvalOptions none;
  none.rpe_delta_m = rpe_delta_m;
  TrajectoryEvalOptions se3 = none;
  se3.alignment = TrajectoryAlignment::kSE3;
  absl::StatusOr<TrajectoryEvalResult> online_none = EvaluateTrajectory(trajectory, gt, none);
  absl::StatusOr<TrajectoryEvalResult> online_se3 = EvaluateTrajectory(trajectory, gt, se3);
  if (online_none.ok() && online_se3.ok()) {
    report->ate_none_m = online_none->ate.translation_m.rmse;
    report->ate_se3_m = online_se3->ate.translation_m.rmse;
    if (!online_se3->rpe.pairs.empty()) {
      report->rpe_m = online_se3->rpe.translation_m.rmse;
      report->rpe_deg = online_se3->rpe.rotation_deg.rmse;
    }
  }
  if (corrected.empty()) return;
  absl::StatusOr<TrajectoryEvalResult> final_none = EvaluateTrajectory(corrected, gt, none);
  absl::StatusOr<TrajectoryEvalResult> final_se3 = EvaluateTrajectory(corrected, gt, se3);
  if (final_none.ok() && final_se3.ok()) {
    report->corrected_ate_none_m = final_none->ate.translation_m.rmse;
    report->corrected_ate_se3_m = final_se3->ate.translation_m.rmse;
  }
}

std::string SlamTrajectoryHeader(const std::string& dataset, const std::string& where,
                                 bool started_from_ground_truth) {
  return absl::StrCat("plenox slam: ", dataset, where,
                      started_from_ground_truth ? " (started at frame 0's ground truth)"
                                                : " (started at the identity)");
}

std::string SlamProgressText(int frame, int frames, const char* state, double milliseconds,
                             int keyframes, int lost, const std::string& reason) {
  return absl::StrFormat("slam %d/%d  %s  %.0f ms  keyframes %d  lost %d%s%s", frame, frames,
                         state, milliseconds, keyframes, lost, reason.empty() ? "" : "  ", reason);
}

std::string SlamFinishingText(const SlamProgress& progress, double seconds) {
  const SlamMapperProgress& m = progress.mapping;
  const std::string rebuild =
      m.loops.rebuilding
          ? absl::StrFormat(", rebuilding at the loop closure's poses (%d/%d iterations)",
                            m.loops.rebuild_iterations, m.loops.rebuild_iteration_budget)
          : "";
  return absl::StrFormat(
      "slam: finishing the map: %d/%d keyframes integrated, %d/%d iterations%s, %.0f s",
      m.keyframes_integrated, m.keyframes, m.mapping_iterations, m.iteration_budget, rebuild,
      seconds);
}

std::string SlamSummaryText(const SlamReport& r, const std::string& tag) {
  std::string memory = absl::StrFormat("map %.1f MB", r.map_mb);
  if (r.keyframe_mb) absl::StrAppendFormat(&memory, ", keyframes %.1f MB", *r.keyframe_mb);
  if (r.peak_rss_mb) absl::StrAppendFormat(&memory, ", peak RSS %.0f MB", *r.peak_rss_mb);
  std::string text = absl::StrFormat(
      "slam: %d frames (%d dropped), %d keyframes, %d OK, %d degraded, %d lost, %d relocalised, "
      "%d waiting; tracking median %.1f ms, p95 %.1f ms; %.2f frames/s wall-clock; %d mapping "
      "iterations; %s%s",
      r.processed, r.dropped, r.keyframes, r.ok, r.degraded, r.lost, r.relocalised, r.waiting,
      r.ms_per_frame_median, r.ms_per_frame_p95, r.fps(), r.mapping_iterations, memory, tag);
  if (r.segments > 0) {
    text += absl::StrFormat(
        "\nslam: %d map segments started after the map was lost, %d joined it again%s",
        r.segments, r.segments_joined,
        r.segments > r.segments_joined
            ? " (the others' keyframes are not in the map, their poses not in its frame)"
            : "");
  }
  if (r.loops_accepted > 0 || r.loops_rejected > 0) {
    text += absl::StrFormat(
        "\nslam: loop closure: %d loops in the pose graph, %d candidates rejected, %d "
        "corrections (%d in place)",
        r.loops_accepted, r.loops_rejected, r.corrections, r.corrections_in_place);
  }
  if (r.ate_none_m && r.ate_se3_m) {
    text += absl::StrFormat("\nslam: ATE %.2f cm (no alignment), %.2f cm (SE(3))",
                            100.0 * *r.ate_none_m, 100.0 * *r.ate_se3_m);
    if (r.rpe_m && r.rpe_deg) {
      text += absl::StrFormat(", RPE %.2f cm / %.2f deg", 100.0 * *r.rpe_m, *r.rpe_deg);
    }
    if (r.corrected_ate_se3_m && r.corrections > 0) {
      text += absl::StrFormat("; in the final frame ATE %.2f cm (SE(3))",
                              100.0 * *r.corrected_ate_se3_m);
    }
  }
  text += r.started_from_ground_truth
              ? "\nslam: started at frame 0's ground-truth pose (no other ground truth used)"
              : "\nslam: no ground truth: started at the identity";
  return text;
}

void PrintSlamResult(const SlamReport& r, bool json, const JsonObject& more) {
  if (!json) {
    std::cout << absl::StrFormat("wrote %s (%d poses)\n", r.trajectory, r.processed);
    return;
  }
  const double unknown = std::nan("");  // written as null
  JsonObject out;
  out.Add("frames", r.frames)
      .Add("processed", r.processed)
      .Add("dropped", r.dropped)
      .Add("keyframes", r.keyframes)
      .Add("ok", r.ok)
      .Add("degraded", r.degraded)
      .Add("lost", r.lost)
      .Add("relocalised", r.relocalised)
      .Add("waiting", r.waiting)
      .Add("segments", r.segments)
      .Add("segments_joined", r.segments_joined)
      .Add("ms_per_frame_median", r.ms_per_frame_median)
      .Add("ms_per_frame_p95", r.ms_per_frame_p95)
      .Add("fps", r.fps())
      .Add("wall_s", r.wall_s)
      .Add("stream_s", r.stream_s > 0.0 ? r.stream_s : unknown)
      .Add("mapping_iterations", r.mapping_iterations)
      .Add("map_mb", r.map_mb)
      .Add("keyframe_mb", r.keyframe_mb.value_or(unknown))
      .Add("peak_rss_mb", r.peak_rss_mb.value_or(unknown))
      .AddBool("started_from_ground_truth", r.started_from_ground_truth)
      .Add("loops_accepted", r.loops_accepted)
      .Add("loops_rejected", r.loops_rejected)
      .Add("corrections", r.corrections)
      .Add("corrections_in_place", r.corrections_in_place)
      .Add("trajectory", r.trajectory)
      .Add("corrected_trajectory", r.corrected_trajectory);
  if (r.ate_none_m) out.Add("ate_none_m", *r.ate_none_m);
  if (r.ate_se3_m) out.Add("ate_se3_m", *r.ate_se3_m);
  if (r.rpe_m) out.Add("rpe_m", *r.rpe_m);
  if (r.rpe_deg) out.Add("rpe_deg", *r.rpe_deg);
  if (r.corrected_ate_none_m) out.Add("corrected_ate_none_m", *r.corrected_ate_none_m);
  if (r.corrected_ate_se3_m) out.Add("corrected_ate_se3_m", *r.corrected_ate_se3_m);
  out.Append(more);
  std::cout << out.str() << "\n";
}

}  // namespace plx::cli

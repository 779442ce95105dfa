// plenox slam: online SLAM over a dataset's frames (core/slam): each frame's pose while the map
// grows, no ground truth used except frame 0's pose as the start when the dataset has one.
#include <algorithm>
#include <chrono>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "app/make_backend.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/slam_output.h"
#include "core/common/status_macros.h"
#include "core/formats/map_file.h"
#include "core/formats/trajectory_file.h"
#include "core/io/atomic_write.h"
#include "core/slam/map_segment_poses.h"
#include "core/slam/slam_dataset.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "slam";

// The flags only the in-process form has: files of what stays on the daemon otherwise (the
// map, the refined keyframe poses), and how this process maps.
void AddInProcessSlamFlags(FlagSet& flags) {
  const SlamOptions d = DefaultSlamOptions();
  flags.Add("map-out", "MAP.plx", "write the final map here, with its keyframes", "")
      .Add("keyframes-out", "F", "write the keyframes' (refined) poses here (TUM format)", "")
      .Add("loops-out", "F",
           "write the map's loop edges here, one per line: the two keyframes' timestamps, the "
           "measured from_T_to (tx ty tz qx qy qz qw), PnP inliers, dense inlier fraction",
           "")
      .Add("frames-out", "F.csv",
           "write one line per processed frame here: frame,timestamp,state,ms,keyframe,"
           "segment,odometry_ms,map_ms,relocalisation_ms,features_ms,reason",
           "")
      .Add("window", "N", "mapping window: half of each batch from the last N keyframes",
           absl::StrCat(d.mapping.mapper.window_keyframes))
      .Add("refine-window", "N",
           "re-align the last N keyframes' poses to the map after each keyframe (0 = off)",
           absl::StrCat(d.refinement.window))
      .Add("mapping-nice", "N", "priority of the mapping thread below tracking (0-19)",
           absl::StrCat(d.mapping_nice))
      .Add("new-segment-after", "N",
           "LOST frames with depth after which the camera starts a new map segment, joined to "
           "the map when it finds it again (0 = never: LOST until relocalised)",
           absl::StrCat(d.new_segment_after_lost_frames))
      .Add("new-segment-after-unconfirmed", "N",
           "frames chained to a map pose the keyframes' features did not confirm (never "
           "keyframes) after which the camera starts a new map segment (0 = never)",
           absl::StrCat(d.new_segment_after_unconfirmed_frames))
      .Add("map-time-budget", "X",
           "hold the map tracker's time on a frame to X times its median over the last frames "
           "(fewer iterations on a costly view instead of a longer frame; 0 = off; off with "
           "--deterministic)",
           absl::StrCat(d.map_time_budget))
      .AddSwitch("no-odometry",
                 "track against the map alone, without the map-free odometry (to measure it)")
      .AddSwitch("no-feature-relocalisation",
                 "relocalise only near the last good pose, not by keyframe features (to "
                 "measure them)");
}

absl::StatusOr<SlamDatasetOptions> OptionsFromFlags(const FlagSet& flags) {
  PLX_ASSIGN_OR_RETURN(SlamDatasetOptions o, SlamOptionsFromFlags(flags));
  SlamOptions& s = o.slam;
  PLX_ASSIGN_OR_RETURN(s.mapping.mapper.window_keyframes, flags.GetInt("window", 0, 1000));
  PLX_ASSIGN_OR_RETURN(s.refinement.window, flags.GetInt("refine-window", 0, 1000));
  PLX_ASSIGN_OR_RETURN(s.mapping_nice, flags.GetInt("mapping-nice", 0, 19));
  PLX_ASSIGN_OR_RETURN(s.new_segment_after_lost_frames,
                       flags.GetInt("new-segment-after", 0, 1000000));
  PLX_ASSIGN_OR_RETURN(s.new_segment_after_unconfirmed_frames,
                       flags.GetInt("new-segment-after-unconfirmed", 0, 1000000));
  PLX_ASSIGN_OR_RETURN(s.map_time_budget, flags.GetDouble("map-time-budget", 0.0, 100.0));
  s.odometry = !flags.GetSwitch("no-odometry");
  s.feature_relocalisation = !flags.GetSwitch("no-feature-relocalisation");
  PLX_RETURN_IF_ERROR(ValidateSlamOptions(s));
  return o;
}

// "a,b" -> "\"a,b\"": a CSV field that may hold commas or quotes.
std::string CsvQuoted(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

// --frames-out: every processed frame's state and ProcessFrame time, for the benchmarks that
// need more than the counts (where the LOST frames fall, the worst frame).
absl::Status WriteFramesCsv(const std::string& path, const std::vector<SlamFrameResult>& results) {
  std::ofstream out(path);
  if (!out) return absl::UnavailableError(absl::StrCat("cannot write ", path));
  out << "frame,timestamp,state,ms,keyframe,segment,odometry_ms,map_ms,relocalisation_ms,"
         "features_ms,rebuilding,reason\n";
  for (const SlamFrameResult& r : results) {
    const SlamFrameTimings& t = r.timings;
    out << absl::StrFormat("%d,%.6f,%s,%.3f,%d,%d,%.3f,%.3f,%.3f,%.3f,%d,%s\n", r.frame,
                           r.timestamp, SlamStateName(r.state), r.milliseconds,
                           r.keyframe ? 1 : 0, r.segment, t.odometry_ms, t.map_ms,
                           t.relocalisation_ms, t.features_ms, r.map_rebuilding ? 1 : 0,
                           CsvQuoted(r.reason));
  }
  out.close();
  if (!out) return absl::UnavailableError(absl::StrCat("failed writing ", path));
  return absl::OkStatus();
}

// --loops-out: the loop edges by their keyframes' timestamps (a benchmark checks each against
// the ground truth: a false loop is one far from it).
absl::Status WriteLoops(const std::string& path, const std::vector<LoopEdge>& loops,
                        const std::vector<StampedPose>& keyframes) {
  std::string text = "# t_from t_to tx ty tz qx qy qz qw inliers depth_inlier_fraction\n";
  for (const LoopEdge& loop : loops) {
    if (loop.from >= static_cast<int>(keyframes.size()) ||
        loop.to >= static_cast<int>(keyframes.size())) {
      continue;
    }
    const Eigen::Vector3d& t = loop.from_T_to.translation();
    const Eigen::Quaterniond& q = loop.from_T_to.rotation();
    absl::StrAppendFormat(&text, "%.6f %.6f %.6f %.6f %.6f %.9f %.9f %.9f %.9f %d %.3f\n",
                          keyframes[loop.from].timestamp, keyframes[loop.to].timestamp, t.x(),
                          t.y(), t.z(), q.x(), q.y(), q.z(), q.w(), loop.inliers,
                          loop.depth_inlier_fraction);
  }
  return WriteFileAtomically(path, text, "cannot write --loops-out");
}

// The slowest frame's ProcessFrame time (every processed frame, LOST ones included).
double MaxFrameMilliseconds(const std::vector<SlamFrameResult>& results) {
  double worst = 0.0;
  for (const SlamFrameResult& r : results) worst = std::max(worst, r.milliseconds);
  return worst;
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
  AddSlamFlags(flags, "voxel size of the map");
  AddInProcessSlamFlags(flags);
  AddBackendFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<SlamDatasetOptions> options = OptionsFromFlags(flags);
  if (!options.ok()) return ReportError(kCommand, options.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  absl::StatusOr<double> rpe_delta = RpeDeltaFromFlags(flags);
  if (!rpe_delta.ok()) return ReportError(kCommand, rpe_delta.status(), true);
  SlamReport report;
  report.trajectory = flags.GetString("out");
  report.corrected_trajectory = flags.GetString("corrected-out");
  for (const std::string& path :
       {report.trajectory, report.corrected_trajectory, flags.GetString("map-out"),
        flags.GetString("keyframes-out"), flags.GetString("frames-out"),
        flags.GetString("loops-out")}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError(kCommand, s);
  }
  const SlamCpuThreads cores = SplitCoresForSlam(
      static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  std::unique_ptr<Backend> backend =
      BackendFromFlagsOrReport(kCommand, flags, &exit_code, cores.tracking);
  if (!backend) return exit_code;
  const SlamSession::BackendFactory mapping_backend =
      MappingBackendFactory(flags, options->slam.deterministic, cores.mapping);
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport(kCommand, flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  // A dataset without depth cannot be mapped: say so before any work.
  if (absl::Status s = CheckSlamDataset(*dataset); !s.ok()) return ReportError(kCommand, s);

  ProgressLine line(!flags.GetSwitch("quiet"));
  int lost = 0;
  const int frames = SlamFrameCount(*dataset, *options);
  std::optional<std::chrono::steady_clock::time_point> finish_start;
  absl::Status streamed_write;  // of the trajectory and --frames-out, when the stream ended
  absl::StatusOr<SlamDatasetResult> result = RunSlamOnDataset(
      *dataset, *backend, mapping_backend, *options,
      [&](const SlamFrameResult& r) {
        lost += r.state == SlamState::kLost;
        line.Update(SlamProgressText(r.frame + 1, frames, SlamStateName(r.state), r.milliseconds,
                                     r.keyframes, lost, r.state == SlamState::kOk ? "" : r.reason));
        return true;
      },
      [&](const SlamProgress& p) {
        if (!finish_start) finish_start = std::chrono::steady_clock::now();
        line.Update(SlamFinishingText(
            p, std::chrono::duration<double>(std::chrono::steady_clock::now() - *finish_start)
                   .count()));
      },
      [&](const SlamDatasetResult& streamed) {
        // The online trajectory (and the per-frame lines) are final once the last frame is
        // tracked: written now, before the map's finishing (minutes after a long run), so an
        // interrupt there loses only the map. A failure is said now and reported at the end.
        streamed_write = WriteTumTrajectory(
            report.trajectory, streamed.trajectory,
            SlamTrajectoryHeader(dataset->name(), "", streamed.started_from_ground_truth));
        if (streamed_write.ok() && !flags.GetString("frames-out").empty()) {
          streamed_write = WriteFramesCsv(flags.GetString("frames-out"), streamed.results);
        }
        if (!streamed_write.ok()) {
          line.Update(absl::StrCat("slam: not written: ", streamed_write.message()));
        }
      });
  if (!result.ok()) return ReportError(kCommand, result.status());
  if (!streamed_write.ok()) return ReportError(kCommand, streamed_write);
  const std::string header =
      SlamTrajectoryHeader(dataset->name(), "", result->started_from_ground_truth);
  // Each frame kept where it was relative to its keyframe, that keyframe at its final pose.
  const std::vector<StampedPose> corrected = CorrectedPoses(result->results, result->keyframes);
  if (!report.corrected_trajectory.empty()) {
    if (absl::Status s = WriteTumTrajectory(report.corrected_trajectory, corrected,
                                            absl::StrCat(header, ", in the map's final frame"));
        !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  if (!flags.GetString("keyframes-out").empty()) {
    if (absl::Status s = WriteTumTrajectory(flags.GetString("keyframes-out"), result->keyframes,
                                            absl::StrCat(header, ", keyframes"));
        !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  if (!flags.GetString("map-out").empty() && result->map != nullptr) {
    // With its keyframes: plenoxd loading the file continues the map (relocalisation by their
    // features, keyframe counts); no version number (the in-process session's are its own).
    MapFileState state;
    if (result->map_keyframes != nullptr) state.keyframes = *result->map_keyframes;
    if (absl::Status s = SaveMap(*result->map, state, flags.GetString("map-out")); !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  if (!flags.GetString("loops-out").empty()) {
    if (absl::Status s = WriteLoops(flags.GetString("loops-out"), result->loops, result->keyframes);
        !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  const SlamProgress& p = result->progress;
  report.frames = result->frames;
  report.processed = static_cast<int>(result->trajectory.size());
  report.dropped = result->dropped;
  report.keyframes = p.mapping.keyframes;
  report.ok = p.tracking.ok;
  report.degraded = p.tracking.degraded;
  report.lost = p.tracking.lost;
  report.relocalised = p.tracking.relocalised;
  report.waiting = p.tracking.waiting;
  report.segments = p.segments.started;
  report.segments_joined = p.segments.joined;
  report.ms_per_frame_median = result->ms_per_frame_median;
  report.ms_per_frame_p95 = result->ms_per_frame_p95;
  report.wall_s = result->wall_s;
  report.stream_s = result->stream_s;
  report.mapping_iterations = p.mapping.mapping_iterations;
  report.map_mb = p.mapping.map_bytes / 1e6;
  report.keyframe_mb = p.mapping.keyframe_bytes / 1e6;
  report.peak_rss_mb = PeakRssMb();
  report.loops_accepted = p.mapping.loops.accepted;
  report.loops_rejected = p.mapping.loops.rejected;
  report.corrections = p.mapping.loops.corrections;
  report.corrections_in_place = p.mapping.loops.in_place;
  report.started_from_ground_truth = result->started_from_ground_truth;
  ScoreSlamTrajectory(*dataset, result->trajectory, corrected, *rpe_delta, &report);
  line.Finish(SlamSummaryText(report, absl::StrCat(" [", BackendText(*backend), "]")));
  PrintSlamResult(report, flags.GetSwitch("json"),
                  JsonObject()
                      .Add("backend", backend->name())
                      .AddBool("deterministic", options->slam.deterministic)
                      .AddBool("realtime", options->realtime)
                      .Add("links_measured", p.mapping.loops.links_measured)
                      .Add("last_measured_edges", p.mapping.loops.last_measured_edges)
                      .Add("ms_per_frame_max", MaxFrameMilliseconds(result->results)));
  return kExitOk;
}

}  // namespace plx::cli

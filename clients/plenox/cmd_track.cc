// plenox track: localise every frame of a dataset in a map.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "core/formats/map_file.h"
#include "core/formats/trajectory_file.h"
#include "core/tracking/track_dataset.h"

namespace plx::cli {

int RunTrack(const std::vector<std::string>& args) {
  FlagSet flags("plenox track",
                "Tracks every frame of a dataset against a map (frozen), starting from frame 0's\n"
                "ground-truth pose when the dataset has one, and writes the trajectory in TUM\n"
                "format (timestamp tx ty tz qx qy qz qw, camera-to-world). Frames the tracker\n"
                "reports LOST keep the predicted pose and are counted.");
  flags.Add("map", "MAP", "map file", std::nullopt, true);
  AddDatasetFlags(flags);
  flags.Add("out", "TRAJ.txt", "trajectory to write", std::nullopt, true);
  AddTrackerFlags(flags);
  AddBackendFlags(flags);
  flags.AddSwitch("json", "print a JSON summary on the last line of stdout")
      .AddSwitch("quiet", "no progress on stderr");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<TrackerOptions> tracker_options = TrackerOptionsFromFlags(flags);
  if (!tracker_options.ok()) return ReportError("track", tracker_options.status(), true);
  const TrackerOptions& options = *tracker_options;
  const std::string mode = flags.GetString("mode");
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError("track", dataset_options.status(), true);
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError("track", s);
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("track", flags, &exit_code);
  if (!backend) return exit_code;

  absl::StatusOr<std::unique_ptr<PlenoxelMap>> map = LoadMap(flags.GetString("map"));
  if (!map.ok()) return ReportError("track", map.status());
  absl::StatusOr<std::unique_ptr<RgbdDataset>> dataset =
      OpenDatasetFromFlags(flags, *dataset_options);
  if (!dataset.ok()) return ReportError("track", dataset.status());

  ProgressLine line(!flags.GetSwitch("quiet"));
  const int total = (*dataset)->size();
  int lost = 0;
  absl::StatusOr<TrackDatasetResult> result = TrackDataset(
      **dataset, **map, *backend, options, [&](int i, const TrackingResult& r) {
        lost += r.state == TrackingState::kLost;
        line.Update(absl::StrFormat("tracking %d/%d  %s  %.0f ms  rays %d/%d  lost %d%s%s", i + 1,
                                    total, TrackingStateName(r.state), r.milliseconds,
                                    r.valid_rays, r.rays, lost, r.reason.empty() ? "" : "  ",
                                    r.reason));
        return true;
      });
  if (!result.ok()) return ReportError("track", result.status());
  if (absl::Status s = WriteTumTrajectory(
          out, result->trajectory,
          absl::StrFormat("plenox track: %s on map %s (mode %s)", (*dataset)->name(),
                          flags.GetString("map"), mode));
      !s.ok()) {
    return ReportError("track", s);
  }
  line.Finish(absl::StrFormat(
      "tracked %d frames: median %.1f ms, p95 %.1f ms per frame, %d lost, %d degraded [%s]%s",
      total, result->ms_per_frame_median, result->ms_per_frame_p95, result->lost,
      result->degraded, BackendText(*backend),
      result->started_from_ground_truth ? "" : " (no ground truth: started at the identity)"));
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("frames", total)
        .Add("ms_per_frame_median", result->ms_per_frame_median)
        .Add("ms_per_frame_p95", result->ms_per_frame_p95)
        .Add("lost", result->lost)
        .Add("degraded", result->degraded)
        .Add("mode", mode)
        .Add("rays", options.rays)
        .Add("iterations", options.iterations)
        .Add("trajectory", out)
        .Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("wrote %s (%d poses)\n", out, total);
  }
  return kExitOk;
}

}  // namespace plx::cli

// plenox track: localise every frame of a dataset in a map.
#include "absl/strings/str_cat.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/track_output.h"
#include "core/formats/trajectory_file.h"
#include "core/tracking/track_dataset.h"

namespace plx::cli {

int RunTrack(const std::vector<std::string>& args) {
  FlagSet flags("plenox track",
                "Tracks every frame of a dataset against a map (frozen), starting from frame 0's\n"
                "ground-truth pose when the dataset has one, and writes the trajectory in TUM\n"
                "format (timestamp tx ty tz qx qy qz qw, camera-to-world). Frames the tracker\n"
                "reports LOST keep the predicted pose and are counted.");
  AddTrackFlags(flags, "MAP", "map file");
  AddBackendFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<TrackerOptions> tracker_options = TrackerOptionsFromFlags(flags);
  if (!tracker_options.ok()) return ReportError("track", tracker_options.status(), true);
  const TrackerOptions& options = *tracker_options;
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError("track", dataset_options.status(), true);
  TrackReport report{.mode = flags.GetString("mode"),
                     .rays = options.rays,
                     .iterations = options.iterations,
                     .trajectory = flags.GetString("out")};
  if (absl::Status s = CheckOutputDirectory(report.trajectory); !s.ok()) {
    return ReportError("track", s);
  }
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("track", flags, &exit_code);
  if (!backend) return exit_code;

  std::unique_ptr<PlenoxelMap> map = LoadMapOrReport("track", flags, *backend, &exit_code);
  if (!map) return exit_code;
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport("track", flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;

  ProgressLine line(!flags.GetSwitch("quiet"));
  report.frames = dataset->size();
  int lost = 0;
  absl::StatusOr<TrackDatasetResult> result = TrackDataset(
      *dataset, *map, *backend, options, [&](int i, const TrackingResult& r) {
        lost += r.state == TrackingState::kLost;
        line.Update(TrackProgressText({.frame = i + 1,
                                       .frames = report.frames,
                                       .state = TrackingStateName(r.state),
                                       .milliseconds = r.milliseconds,
                                       .valid_rays = r.valid_rays,
                                       .rays = r.rays,
                                       .lost = lost,
                                       .reason = r.reason}));
        return true;
      });
  if (!result.ok()) return ReportError("track", result.status());
  if (absl::Status s = WriteTrackTrajectory(report, result->trajectory, dataset->name(),
                                            flags.GetString("map"));
      !s.ok()) {
    return ReportError("track", s);
  }
  report.ms_per_frame_median = result->ms_per_frame_median;
  report.ms_per_frame_p95 = result->ms_per_frame_p95;
  report.lost = result->lost;
  report.degraded = result->degraded;
  report.started_from_ground_truth = result->started_from_ground_truth;
  line.Finish(TrackSummaryText(report, "", absl::StrCat(" [", BackendText(*backend), "]")));
  PrintTrackResult(report, flags.GetSwitch("json"), JsonObject(),
                   JsonObject().Add("backend", backend->name()));
  return kExitOk;
}

}  // namespace plx::cli

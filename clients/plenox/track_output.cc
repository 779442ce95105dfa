#include "clients/plenox/track_output.h"

#include <iostream>

#include "absl/strings/str_format.h"
#include "core/formats/trajectory_file.h"

namespace plx::cli {

void AddTrackFlags(FlagSet& flags, const std::string& map_value, const std::string& map_help) {
  flags.Add("map", map_value, map_help, std::nullopt, true);
  AddDatasetFlags(flags);
  flags.Add("out", "TRAJ.txt", "trajectory to write", std::nullopt, true);
  AddTrackerFlags(flags);
}

std::string TrackProgressText(const TrackProgress& p) {
  return absl::StrFormat("tracking %d/%d  %s  %.0f ms  rays %d/%d  lost %d%s%s", p.frame,
                         p.frames, p.state, p.milliseconds, p.valid_rays, p.rays, p.lost,
                         p.reason.empty() ? "" : "  ", p.reason);
}

absl::Status WriteTrackTrajectory(const TrackReport& report, const std::vector<StampedPose>& poses,
                                  const std::string& dataset, const std::string& map) {
  return WriteTumTrajectory(report.trajectory, poses,
                            absl::StrFormat("plenox track: %s on map %s (mode %s)", dataset, map,
                                            report.mode));
}

std::string TrackSummaryText(const TrackReport& r, const std::string& where,
                             const std::string& tag) {
  return absl::StrFormat(
      "tracked %d frames%s: median %.1f ms, p95 %.1f ms per frame, %d lost, %d degraded%s%s",
      r.frames, where, r.ms_per_frame_median, r.ms_per_frame_p95, r.lost, r.degraded, tag,
      r.started_from_ground_truth ? "" : " (no ground truth: started at the identity)");
}

void PrintTrackResult(const TrackReport& r, bool json, const JsonObject& more_times,
                      const JsonObject& where) {
  if (!json) {
    std::cout << absl::StrFormat("wrote %s (%d poses)\n", r.trajectory, r.frames);
    return;
  }
  JsonObject out;
  out.Add("frames", r.frames)
      .Add("ms_per_frame_median", r.ms_per_frame_median)
      .Add("ms_per_frame_p95", r.ms_per_frame_p95)
      .Append(more_times)
      .Add("lost", r.lost)
      .Add("degraded", r.degraded);
  if (r.dropped) out.Add("dropped", *r.dropped);
  out.Add("mode", r.mode)
      .Add("rays", r.rays)
      .Add("iterations", r.iterations)
      .Add("trajectory", r.trajectory)
      .Append(where);
  std::cout << out.str() << "\n";
}

}  // namespace plx::cli

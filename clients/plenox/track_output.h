// What `plenox track` takes and reports, in-process (cmd_track.cc) and on a daemon
// (remote_track.cc): the shared flags, the progress line, the trajectory file's header, the
// summary line and the JSON keys, written once so that the two forms cannot drift apart.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "clients/plenox/cli_common.h"
#include "core/geometry/stamped_pose.h"

namespace plx::cli {

// --map (`map_value` and `map_help` say whether it is a file or a map on the daemon),
// the dataset flags, --out and the tracker flags, in that order.
void AddTrackFlags(FlagSet& flags, const std::string& map_value, const std::string& map_help);

// One progress line: "tracking 5/40  OK  12 ms  rays 1985/2048  lost 0".
struct TrackProgress {
  int frame = 0;  // 1-based
  int frames = 0;
  const char* state = "";
  double milliseconds = 0.0;
  int valid_rays = 0;
  int rays = 0;
  int lost = 0;        // so far
  std::string reason;  // why DEGRADED or LOST; empty otherwise
};
std::string TrackProgressText(const TrackProgress& progress);

// What a finished track reports. Times and counts are over frames 1.. (frame 0 is the start).
struct TrackReport {
  std::string mode;        // --mode
  int rays = 0;            // the tracker settings that ran
  int iterations = 0;
  std::string trajectory;  // --out
  int frames = 0;
  double ms_per_frame_median = 0.0;
  double ms_per_frame_p95 = 0.0;
  int lost = 0;
  int degraded = 0;
  std::optional<int64_t> dropped = std::nullopt;  // frames the daemon dropped (remote only)
  bool started_from_ground_truth = true;
};

// Writes `poses` to report.trajectory, headed "plenox track: DATASET on map MAP (mode M)".
absl::Status WriteTrackTrajectory(const TrackReport& report, const std::vector<StampedPose>& poses,
                                  const std::string& dataset, const std::string& map);

// "tracked 40 frames<where>: median 9.1 ms, p95 14.0 ms per frame, 0 lost, 1 degraded<tag>",
// and a note when there was no ground truth to start from.
std::string TrackSummaryText(const TrackReport& report, const std::string& where,
                             const std::string& tag);

// The result on stdout: with --json the summary object (frames and times, then `more_times`,
// counts, settings and trajectory, then `where`), else "wrote TRAJ (N poses)".
void PrintTrackResult(const TrackReport& report, bool json, const JsonObject& more_times,
                      const JsonObject& where);

}  // namespace plx::cli

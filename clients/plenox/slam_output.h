// What `plenox slam` reports: the progress line, the summary line and the JSON keys, written
// once for the in-process command (cmd_slam.cc) and the daemon's form to come.
#pragma once

#include <optional>
#include <string>

#include "clients/plenox/cli_common.h"

namespace plx::cli {

struct SlamReport {
  std::string trajectory;  // --out
  int frames = 0;          // in the dataset (or --max-frames)
  int processed = 0;
  int dropped = 0;         // --realtime: skipped while the tracker was behind
  int keyframes = 0;
  int ok = 0, degraded = 0, lost = 0, relocalised = 0;
  double ms_per_frame_median = 0.0;
  double ms_per_frame_p95 = 0.0;
  double wall_s = 0.0;
  int mapping_iterations = 0;
  double map_mb = 0.0;
  double keyframe_mb = 0.0;
  double peak_rss_mb = 0.0;
  bool started_from_ground_truth = false;
  // With ground truth (eval-traj's definitions).
  std::optional<double> ate_none_m, ate_se3_m, rpe_m, rpe_deg;

  double fps() const { return wall_s > 0.0 ? processed / wall_s : 0.0; }
};

// "slam 41/120  OK  23 ms  keyframes 5  lost 0".
std::string SlamProgressText(int frame, int frames, const char* state, double milliseconds,
                             int keyframes, int lost, const std::string& reason);

// The summary line(s) on stderr.
std::string SlamSummaryText(const SlamReport& report, const std::string& tag);

// stdout: with --json one object with the keys of the report, else "wrote TRAJ (N poses)".
void PrintSlamResult(const SlamReport& report, bool json, const JsonObject& more);

}  // namespace plx::cli

// What `plenox slam` takes and reports, in-process (cmd_slam.cc) and on a daemon
// (remote_slam.cc): the shared flags, the check of the dataset, the scoring against ground
// truth, the progress line, the summary line and the JSON keys, written once so that the two
// forms cannot drift apart.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "clients/plenox/cli_common.h"
#include "core/datasets/dataset.h"
#include "core/geometry/stamped_pose.h"
#include "core/slam/slam_dataset.h"

namespace plx::cli {

// The flags both forms take, in this order: --out, --corrected-out; the replay (--realtime,
// --speed, --deterministic, --max-frames); the mapping budget (--iterations-per-keyframe); the
// keyframe thresholds (--kf-translation, --kf-rotation, --kf-unmapped, --kf-interval);
// --no-loop-closure; --rpe-delta; the tracker flags (--mode, --rays, --iterations) and
// --voxel-size (`voxel_help`).
void AddSlamFlags(FlagSet& flags, const std::string& voxel_help);

// The options those flags ask for, on top of DefaultSlamOptions (the flags the in-process form
// alone has are the caller's). Errors are usage errors: a value out of range, --realtime with
// --deterministic, options SLAM refuses (ValidateSlamOptions).
absl::StatusOr<SlamDatasetOptions> SlamOptionsFromFlags(const FlagSet& flags);
absl::StatusOr<double> RpeDeltaFromFlags(const FlagSet& flags);

// What SLAM cannot run on, found before any frame is processed or sent: a dataset without
// frames, or one where no frame has valid depth (InvalidArgument naming it). Frames are loaded
// until one has depth: usually frame 0 alone.
absl::Status CheckSlamDataset(const RgbdDataset& dataset);

// The number of frames a run goes through: the dataset's, or --max-frames when fewer.
int SlamFrameCount(const RgbdDataset& dataset, const SlamDatasetOptions& options);

struct SlamReport {
  std::string trajectory;  // --out
  std::string corrected_trajectory;  // --corrected-out ("": not written)
  int frames = 0;          // in the dataset (or --max-frames)
  int processed = 0;
  int dropped = 0;         // --realtime: skipped while the tracker was behind
  int keyframes = 0;
  int ok = 0, degraded = 0, lost = 0, relocalised = 0;
  int waiting = 0;  // before a frame had enough depth to start the map (SlamState::kWaiting)
  // Map segments started after the map was lost for good, and of them joined to the main map
  // again (docs/SLAM.md, "Map segments").
  int segments = 0, segments_joined = 0;
  double ms_per_frame_median = 0.0;
  double ms_per_frame_p95 = 0.0;
  double wall_s = 0.0;
  // The frames' part of wall_s (the final mapping after the last frame excluded); 0 when not
  // known (the daemon's stream reports the whole).
  double stream_s = 0.0;
  int mapping_iterations = 0;
  double map_mb = 0.0;
  // Known in-process only (the daemon reports neither): null in the JSON, left out of the
  // summary otherwise.
  std::optional<double> keyframe_mb;
  std::optional<double> peak_rss_mb;
  // Loop closure on the map (docs/SLAM.md, "Loop closure"): loop edges in its pose graph,
  // candidates rejected, corrected maps published and of those the ones applied in the running
  // map without a rebuild.
  int loops_accepted = 0, loops_rejected = 0, corrections = 0, corrections_in_place = 0;
  bool started_from_ground_truth = false;
  // With ground truth (eval-traj's definitions): the online trajectory's, and the ATE of the
  // trajectory in the map's final frame (what --corrected-out writes).
  std::optional<double> ate_none_m, ate_se3_m, rpe_m, rpe_deg;
  std::optional<double> corrected_ate_none_m, corrected_ate_se3_m;

  // Frames per second of the stream, mapping running beside it.
  double fps() const {
    const double s = stream_s > 0.0 ? stream_s : wall_s;
    return s > 0.0 ? processed / s : 0.0;
  }
};

// ATE (no alignment and SE(3)) and RPE (pairs `rpe_delta_m` of path apart) of `trajectory`
// against the dataset's ground truth, as eval-traj computes them, into `report`; nothing when
// the dataset has fewer than 3 ground-truth poses.
// `corrected`: the trajectory in the map's final frame, scored into corrected_ate_* (empty: not).
void ScoreSlamTrajectory(const RgbdDataset& dataset, const std::vector<StampedPose>& trajectory,
                         const std::vector<StampedPose>& corrected, double rpe_delta_m,
                         SlamReport* report);

// The trajectory file's header: "plenox slam: DATASET<where> (started at ...)".
std::string SlamTrajectoryHeader(const std::string& dataset, const std::string& where,
                                 bool started_from_ground_truth);

// "slam 41/120  OK  23 ms  keyframes 5  lost 0".
std::string SlamProgressText(int frame, int frames, const char* state, double milliseconds,
                             int keyframes, int lost, const std::string& reason);

// While the map is finished after the last frame: "slam: finishing the map: 60/71 keyframes
// integrated, 1200/2130 iterations, rebuilding at the loop closure's poses (300/2100
// iterations), 35 s".
std::string SlamFinishingText(const SlamProgress& progress, double seconds);

// The summary line(s) on stderr.
std::string SlamSummaryText(const SlamReport& report, const std::string& tag);

// stdout: with --json one object with the keys of the report, else "wrote TRAJ (N poses)".
void PrintSlamResult(const SlamReport& report, bool json, const JsonObject& more);

}  // namespace plx::cli

#include "clients/plenox/slam_output.h"

#include <iostream>

#include "absl/strings/str_format.h"

namespace plx::cli {

std::string SlamProgressText(int frame, int frames, const char* state, double milliseconds,
                             int keyframes, int lost, const std::string& reason) {
  return absl::StrFormat("slam %d/%d  %s  %.0f ms  keyframes %d  lost %d%s%s", frame, frames,
                         state, milliseconds, keyframes, lost, reason.empty() ? "" : "  ", reason);
}

std::string SlamSummaryText(const SlamReport& r, const std::string& tag) {
  std::string text = absl::StrFormat(
      "slam: %d frames (%d dropped), %d keyframes, %d OK, %d degraded, %d lost, %d relocalised; "
      "tracking median %.1f ms, p95 %.1f ms; %.2f frames/s wall-clock; %d mapping iterations; "
      "map %.1f MB, keyframes %.1f MB, peak RSS %.0f MB%s",
      r.processed, r.dropped, r.keyframes, r.ok, r.degraded, r.lost, r.relocalised,
      r.ms_per_frame_median, r.ms_per_frame_p95, r.fps(), r.mapping_iterations, r.map_mb,
      r.keyframe_mb, r.peak_rss_mb, tag);
  if (r.ate_none_m && r.ate_se3_m) {
    text += absl::StrFormat("\nslam: ATE %.2f cm (no alignment), %.2f cm (SE(3))",
                            100.0 * *r.ate_none_m, 100.0 * *r.ate_se3_m);
    if (r.rpe_m && r.rpe_deg) {
      text += absl::StrFormat(", RPE %.2f cm / %.2f deg", 100.0 * *r.rpe_m, *r.rpe_deg);
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
  JsonObject out;
  out.Add("frames", r.frames)
      .Add("processed", r.processed)
      .Add("dropped", r.dropped)
      .Add("keyframes", r.keyframes)
      .Add("ok", r.ok)
      .Add("degraded", r.degraded)
      .Add("lost", r.lost)
      .Add("relocalised", r.relocalised)
      .Add("ms_per_frame_median", r.ms_per_frame_median)
      .Add("ms_per_frame_p95", r.ms_per_frame_p95)
      .Add("fps", r.fps())
      .Add("wall_s", r.wall_s)
      .Add("mapping_iterations", r.mapping_iterations)
      .Add("map_mb", r.map_mb)
      .Add("keyframe_mb", r.keyframe_mb)
      .Add("peak_rss_mb", r.peak_rss_mb)
      .AddBool("started_from_ground_truth", r.started_from_ground_truth)
      .Add("trajectory", r.trajectory);
  if (r.ate_none_m) out.Add("ate_none_m", *r.ate_none_m);
  if (r.ate_se3_m) out.Add("ate_se3_m", *r.ate_se3_m);
  if (r.rpe_m) out.Add("rpe_m", *r.rpe_m);
  if (r.rpe_deg) out.Add("rpe_deg", *r.rpe_deg);
  out.Append(more);
  std::cout << out.str() << "\n";
}

}  // namespace plx::cli

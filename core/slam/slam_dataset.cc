#include "core/slam/slam_dataset.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <thread>

#include "absl/strings/str_cat.h"
#include "core/common/percentile.h"
#include "core/common/status_macros.h"
#include "core/slam/map_segment_poses.h"

namespace plx {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

absl::StatusOr<SlamDatasetResult> RunSlamOnDataset(
    const RgbdDataset& dataset, Backend& tracking_backend,
    const SlamSession::BackendFactory& make_mapping_backend, const SlamDatasetOptions& options,
    const std::function<bool(const SlamFrameResult&)>& progress,
    const std::function<void(const SlamProgress&)>& finishing,
    const std::function<void(const SlamDatasetResult&)>& streamed) {
  if (dataset.size() == 0) return absl::InvalidArgumentError("the dataset has no frames");
  if (options.realtime && !(options.speed > 0.0 && std::isfinite(options.speed))) {
    return absl::InvalidArgumentError(
        absl::StrCat("realtime speed must be positive, got ", options.speed));
  }
  if (options.max_frames < 0) return absl::InvalidArgumentError("max_frames must not be negative");
  if (!(options.finishing_report_s > 0.0 && std::isfinite(options.finishing_report_s))) {
    return absl::InvalidArgumentError(absl::StrCat("finishing_report_s must be positive, got ",
                                                   options.finishing_report_s));
  }
  SlamDatasetResult out;
  out.frames = options.max_frames > 0 ? std::min(options.max_frames, dataset.size())
                                      : dataset.size();
  SlamOptions slam = options.slam;
  slam.live_source = slam.live_source || options.realtime;
  const std::optional<SE3> start = dataset.ground_truth(0);
  if (options.start_from_ground_truth && start) {
    slam.initial_pose = *start;
    out.started_from_ground_truth = true;
  }
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<SlamSession> session,
                       SlamSession::Create(slam, &tracking_backend, make_mapping_backend));
  const PinholeIntrinsics& k = dataset.calibration().pinhole;
  const auto wall_start = std::chrono::steady_clock::now();
  const double t0 = dataset.timestamp(0);
  std::vector<double> ms;
  int i = 0;
  while (i < out.frames) {
    PLX_ASSIGN_OR_RETURN(RgbdFrame frame, dataset.LoadFrame(i));
    frame.ground_truth.reset();  // SLAM sees no ground truth
    PLX_ASSIGN_OR_RETURN(SlamFrameResult r, session->ProcessFrame(std::move(frame), k));
    ms.push_back(r.milliseconds);
    out.results.push_back(r);
    if (progress && !progress(r)) return absl::CancelledError("SLAM cancelled");
    int next = i + 1;
    if (options.realtime && next < out.frames) {
      // The sensor's clock: frame j arrives at (t_j - t_0) / speed after the start.
      const double now = SecondsSince(wall_start);
      const auto due = [&](int j) { return (dataset.timestamp(j) - t0) / options.speed; };
      while (next + 1 < out.frames && due(next + 1) <= now) {
        ++next;
        ++out.dropped;
      }
      if (due(next) > now) {
        std::this_thread::sleep_for(std::chrono::duration<double>(due(next) - now));
      }
    }
    i = next;
  }
  out.stream_s = SecondsSince(wall_start);
  out.trajectory = PosesInMainMap(out.results);
  if (streamed) streamed(out);
  if (finishing) {
    // Finish blocks until the map is done; progress() may be read from any thread meanwhile.
    finishing(session->progress());
    std::future<absl::Status> finished =
        std::async(std::launch::async, [&session] { return session->Finish(); });
    const auto every = std::chrono::duration<double>(options.finishing_report_s);
    while (finished.wait_for(every) != std::future_status::ready) finishing(session->progress());
    PLX_RETURN_IF_ERROR(finished.get());
    finishing(session->progress());
  } else {
    PLX_RETURN_IF_ERROR(session->Finish());
  }
  out.wall_s = SecondsSince(wall_start);
  out.map = session->latest_map();
  out.map_keyframes = session->latest_map_keyframes();
  out.keyframes = session->keyframe_poses();
  out.loops = session->loops();
  out.progress = session->progress();
  out.ms_per_frame_median = Percentile(ms, 0.5);
  out.ms_per_frame_p95 = Percentile(ms, 0.95);
  return out;
}

}  // namespace plx

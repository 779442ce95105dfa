#include "core/tracking/track_dataset.h"

#include "core/common/percentile.h"
#include "core/common/status_macros.h"

namespace plx {

absl::StatusOr<TrackDatasetResult> TrackDataset(
    const RgbdDataset& dataset, const PlenoxelMap& map, Backend& backend,
    const TrackerOptions& options,
    const std::function<bool(int, const TrackingResult&)>& progress) {
  PLX_RETURN_IF_ERROR(Tracker::ValidateOptions(options));
  if (dataset.size() == 0) return absl::InvalidArgumentError("the dataset has no frames");
  if (map.grid.num_bricks() == 0) return absl::FailedPreconditionError("the map is empty");
  Tracker tracker(&map, &backend, options);
  TrackDatasetResult out;
  const std::optional<SE3> start = dataset.ground_truth(0);
  out.started_from_ground_truth = start.has_value();
  const SE3 initial = start.value_or(SE3::Identity());
  tracker.Reset(initial, dataset.timestamp(0));
  TrackingResult first;
  first.pose = initial;
  first.state = TrackingState::kOk;
  first.reason = start ? "starting pose (ground truth)" : "starting pose (identity)";
  out.trajectory.push_back({dataset.timestamp(0), initial});
  out.results.push_back(first);
  if (progress && !progress(0, first)) return absl::CancelledError("tracking cancelled");
  std::vector<double> ms;
  const PinholeIntrinsics& k = dataset.calibration().pinhole;
  for (int i = 1; i < dataset.size(); ++i) {
    PLX_ASSIGN_OR_RETURN(RgbdFrame frame, dataset.LoadFrame(i));
    PLX_ASSIGN_OR_RETURN(TrackingResult r, tracker.Track(frame, k));
    ms.push_back(r.milliseconds);
    out.lost += r.state == TrackingState::kLost;
    out.degraded += r.state == TrackingState::kDegraded;
    out.trajectory.push_back({frame.timestamp, r.pose});
    out.results.push_back(r);
    if (progress && !progress(i, r)) return absl::CancelledError("tracking cancelled");
  }
  out.ms_per_frame_median = Percentile(ms, 0.5);
  out.ms_per_frame_p95 = Percentile(ms, 0.95);
  return out;
}

}  // namespace plx

// The localisation job over a dataset (DESIGN.md §11): every frame tracked against a frozen
// map, starting from frame 0's ground-truth pose when the dataset has one.
#pragma once

#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/tracking/tracker.h"

namespace plx {

struct TrackDatasetResult {
  std::vector<StampedPose> trajectory;  // one pose per frame, world_T_camera
  std::vector<TrackingResult> results;  // per frame (frame 0: the starting pose, OK)
  bool started_from_ground_truth = false;
  double ms_per_frame_median = 0.0;     // tracking time, image decoding excluded
  double ms_per_frame_p95 = 0.0;
  int lost = 0;
  int degraded = 0;
};

// `progress(frame_index, result)` after every frame; returning false cancels.
absl::StatusOr<TrackDatasetResult> TrackDataset(
    const RgbdDataset& dataset, const PlenoxelMap& map, Backend& backend,
    const TrackerOptions& options,
    const std::function<bool(int, const TrackingResult&)>& progress = nullptr);

}  // namespace plx

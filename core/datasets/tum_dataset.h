// TUM RGB-D layout (../shared/data/README.md):
//   rgb/<t>.png, depth/<t>.png, rgb.txt and depth.txt ("timestamp filename"),
//   optional associations.txt ("t_rgb rgb/<t>.png t_depth depth/<t>.png"),
//   optional groundtruth.txt ("timestamp tx ty tz qx qy qz qw", camera-to-world),
//   intrinsics.txt (or DatasetOptions::calibration).
// Frames are ordered by, and stamped with, the colour timestamp.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"

namespace plx {

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenTumDataset(const std::string& directory,
                                                            const DatasetOptions& options);

// Pairs entries of `first` and `second` whose timestamps differ by at most `max_difference`,
// each entry used at most once, greedily by smallest difference (TUM's associate.py). Returns
// (index in first, index in second) sorted by the first timestamp.
std::vector<std::pair<int, int>> AssociateTimestamps(const std::vector<double>& first,
                                                     const std::vector<double>& second,
                                                     double max_difference);

// The pose at `time` from `samples` sorted by timestamp: interpolated (linear translation,
// slerp rotation) between the two samples bracketing `time` when both lie within
// `max_difference`, else the nearest sample within `max_difference`, else nullopt.
std::optional<SE3> PoseAtTime(const std::vector<StampedPose>& samples, double time,
                              double max_difference);

}  // namespace plx

// Replica as rendered and released by NICE-SLAM:
//   results/frame%06d.jpg (or .png), results/depth%06d.png (16-bit),
//   traj.txt: one row-major 4x4 camera-to-world matrix per line (OpenCV axes), one per frame,
//   intrinsics.txt (or DatasetOptions::calibration): NICE-SLAM keeps the calibration in a
//   config file, which is not read here.
// Replica renders carry no timing; frame n is stamped n / 30 s.
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"

namespace plx {

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenReplicaDataset(const std::string& directory,
                                                                const DatasetOptions& options);

}  // namespace plx

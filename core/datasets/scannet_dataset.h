// ScanNet as exported by its SensReader (the layout Vox-Fusion and SplaTAM read):
//   color/<i>.jpg, depth/<i>.png (16-bit, millimetres), pose/<i>.txt (4x4 camera-to-world;
//   ScanNet marks frames without tracking with inf/nan, which become "no ground truth"),
//   intrinsic/intrinsic_depth.txt.
// Frames are sorted by the integer <i> and stamped i / 30 s. Colour (1296x968) is resized with
// area averaging to the depth size (640x480), so the calibration is the depth camera's: from
// intrinsics.txt or DatasetOptions::calibration when given, else intrinsic_depth.txt with depth
// scale 1000 and the size of the depth images.
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"

namespace plx {

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenScanNetDataset(const std::string& directory,
                                                                const DatasetOptions& options);

}  // namespace plx

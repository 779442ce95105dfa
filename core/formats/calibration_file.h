// intrinsics.txt: the per-sequence calibration file of ../shared/data/README.md.
//
//   # fx fy cx cy width height depth_scale k1 k2 p1 p2 k3
//   535.4 539.2 320.1 247.6 640 480 5000.0 0 0 0 0 0
//
// '#' lines are comments; exactly one data line follows. The distortion block may be left out
// (7 numbers), which means no distortion.
#pragma once

#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"

namespace plx {

inline constexpr char kCalibrationFileName[] = "intrinsics.txt";

// Reads and validates (ValidateCalibration) a calibration file. Errors name the file and line.
absl::StatusOr<CameraCalibration> ReadCalibrationFile(const std::string& path);

// The file's text: a comment header and the data line, numbers printed to round-trip exactly.
std::string FormatCalibrationFile(const CameraCalibration& calibration);
absl::Status WriteCalibrationFile(const std::string& path, const CameraCalibration& calibration);

// The calibration for the sequence in `directory`: `override_calibration` (from CLI flags) when
// set, else <directory>/intrinsics.txt. When neither exists the NotFoundError says so and how
// to pass the calibration by flags.
absl::StatusOr<CameraCalibration> LoadDatasetCalibration(
    const std::string& directory, const std::optional<CameraCalibration>& override_calibration);

// The NotFoundError LoadDatasetCalibration returns, for loaders with further fallbacks.
absl::Status MissingCalibrationError(const std::string& directory);

// A 4x4 (or 3x3) camera matrix file as in ScanNet's intrinsic/intrinsic_depth.txt. Returns
// fx, fy, cx, cy; width and height are left 0 for the caller to fill from the images.
absl::StatusOr<PinholeIntrinsics> ReadIntrinsicMatrixFile(const std::string& path);

}  // namespace plx

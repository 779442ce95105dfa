// Camera calibration as read from a dataset's intrinsics.txt or from flags.
#pragma once

#include <string>

#include "absl/status/statusor.h"

namespace plx {

// The largest image side a calibration may have (ValidateCalibration; the daemon's frames and
// renders).
inline constexpr int kMaxImageSide = 16384;

// Pinhole model; pixel centres sit at (u + 0.5, v + 0.5) (DESIGN.md §4).
struct PinholeIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;

  bool operator==(const PinholeIntrinsics&) const = default;
};

// Brown-Conrady coefficients in OpenCV order (k1, k2, p1, p2, k3).
struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
  bool operator==(const Distortion&) const = default;
};

// Everything needed to turn a sensor's images into metric RGB-D frames.
struct CameraCalibration {
  PinholeIntrinsics pinhole;
  double depth_scale = 1000.0;  // sensor units per metre (TUM 5000, ScanNet 1000, Replica 6553.5)
  Distortion distortion;
  bool operator==(const CameraCalibration&) const = default;
};

// Checks focal lengths, principal point, size and depth scale are finite and positive.
absl::Status ValidateCalibration(const CameraCalibration& calibration);

// Parses "fx fy cx cy w h" (the CLI's --intrinsics flag).
absl::StatusOr<PinholeIntrinsics> ParsePinholeIntrinsics(const std::string& text);

}  // namespace plx

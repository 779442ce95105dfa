// Poses as text: "tx ty tz qx qy qz qw" (the TUM trajectory order, world_T_camera).
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"

namespace plx {

// Parses 7 numbers separated by spaces or commas; the quaternion is normalised and must not be
// (near) zero; every value must be finite.
absl::StatusOr<SE3> ParsePoseText(const std::string& text);

// The inverse of ParsePoseText, with enough digits to round-trip a double-precision pose to 1e-9.
std::string FormatPoseText(const SE3& pose);

}  // namespace plx

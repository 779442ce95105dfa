// Trajectories as TUM text files: one pose per line, "timestamp tx ty tz qx qy qz qw"
// (seconds; world_T_camera, i.e. the camera centre and orientation in the world; Hamilton
// quaternion, scalar last). This is the format of TUM RGB-D's groundtruth.txt and the one evo's
// `evo_ape tum ...` reads, so files written here can be checked with evo directly.
#pragma once

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/geometry/stamped_pose.h"

namespace plx {

// Reads a TUM trajectory. Blank lines and lines starting with '#' are skipped. Every other line
// must hold exactly 8 finite numbers; the quaternion must not be (near) zero and is normalised
// (files rounded to 4 decimals, like TUM's ground truth, are accepted as they are). The poses are
// returned sorted by timestamp; two lines with the same timestamp are an error. Errors are
// InvalidArgument "path:line: what is wrong" (NotFound when the file does not exist).
// An empty file (only comments) gives an empty vector.
absl::StatusOr<std::vector<StampedPose>> ReadTumTrajectory(const std::string& path);

// Writes `poses` as a TUM trajectory: `header_comment` first (each of its lines prefixed with
// "# "; nothing when empty), then one line per pose with the timestamp as "%.6f" and the other
// seven values with 9 significant digits, the quaternion sign chosen so that qw >= 0.
// The poses must be finite and their timestamps strictly increasing at the written precision
// (1 us), so that ReadTumTrajectory reads the file back; InvalidArgument otherwise.
// The file is written to "<path>.tmp.<pid>" in the same folder, flushed to disk and renamed over
// `path`, so readers never see a partial file and a failed write leaves `path` as it was.
// NotFound when the folder does not exist.
absl::Status WriteTumTrajectory(const std::string& path, const std::vector<StampedPose>& poses,
                                const std::string& header_comment = "");

}  // namespace plx

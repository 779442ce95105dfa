// Poses the engine accepts: finite, with the camera inside the world extent
// (core/common/world_extent.h). Mapping checks every keyframe with it, so no caller can place
// bricks where the grid's coordinates would wrap around; the daemon checks client poses with it
// first, to name the offending field.
#pragma once

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "core/geometry/se3.h"

namespace plx {

// InvalidArgument "<field>: ..." when the pose is not finite or its translation is outside
// kWorldExtentMeters on some axis.
absl::Status CheckPoseInsideWorld(const SE3& world_T_camera, absl::string_view field);

}  // namespace plx

#include "core/geometry/world_pose.h"

#include "absl/strings/str_cat.h"
#include "core/common/world_extent.h"

namespace plx {

absl::Status CheckPoseInsideWorld(const SE3& pose, absl::string_view field) {
  if (!pose.IsFinite()) return absl::InvalidArgumentError(absl::StrCat(field, ": not finite"));
  const Eigen::Vector3d& t = pose.translation();
  return CheckInsideWorld(t.x(), t.y(), t.z(), absl::StrCat(field, ": translation"));
}

}  // namespace plx

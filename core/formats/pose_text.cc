#include "core/formats/pose_text.h"

#include <cmath>
#include <optional>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"

namespace plx {

absl::StatusOr<SE3> ParsePoseText(const std::string& text) {
  std::vector<std::string> parts = absl::StrSplit(text, absl::ByAnyChar(" ,\t"), absl::SkipEmpty());
  if (parts.size() != 7) {
    return absl::InvalidArgumentError(
        absl::StrCat("a pose needs 7 numbers \"tx ty tz qx qy qz qw\", got ", parts.size(),
                     " in \"", text, "\""));
  }
  double v[7];
  for (int i = 0; i < 7; ++i) {
    if (!absl::SimpleAtod(parts[i], &v[i]) || !std::isfinite(v[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("pose: \"", parts[i], "\" is not a finite number"));
    }
  }
  const std::optional<Eigen::Quaterniond> q =
      UnitQuaternion(Eigen::Quaterniond(v[6], v[3], v[4], v[5]), 1e-6);
  if (!q) return absl::InvalidArgumentError("pose: the quaternion is zero");
  return SE3(*q, Eigen::Vector3d(v[0], v[1], v[2]));
}

std::string FormatPoseText(const SE3& pose) {
  Eigen::Quaterniond q = pose.rotation();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d& t = pose.translation();
  return absl::StrFormat("%.9f %.9f %.9f %.9f %.9f %.9f %.9f", t.x(), t.y(), t.z(), q.x(), q.y(),
                         q.z(), q.w());
}

}  // namespace plx

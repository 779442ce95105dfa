#include "proto/pose_codec.h"

#include <cmath>
#include <optional>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace plx {

void PoseToProto(const SE3& pose, ::plenoxd::v1::Pose* out) {
  // SE3 keeps its rotation normalised; normalising again costs nothing and keeps this function
  // the one place that states the convention.
  Eigen::Quaterniond q = pose.rotation().normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d& t = pose.translation();
  out->set_tx(t.x());
  out->set_ty(t.y());
  out->set_tz(t.z());
  out->set_qx(q.x());
  out->set_qy(q.y());
  out->set_qz(q.z());
  out->set_qw(q.w());
}

absl::StatusOr<SE3> PoseFromProto(const ::plenoxd::v1::Pose& p, const std::string& field) {
  const double values[7] = {p.tx(), p.ty(), p.tz(), p.qx(), p.qy(), p.qz(), p.qw()};
  const char* names[7] = {"tx", "ty", "tz", "qx", "qy", "qz", "qw"};
  for (int i = 0; i < 7; ++i) {
    if (!std::isfinite(values[i])) {
      return absl::InvalidArgumentError(absl::StrCat(field, ".", names[i], ": not finite"));
    }
  }
  const std::optional<Eigen::Quaterniond> q =
      UnitQuaternion(Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()), 1e-6);
  if (!q) return absl::InvalidArgumentError(absl::StrCat(field, ": the quaternion is zero"));
  return SE3(*q, Eigen::Vector3d(p.tx(), p.ty(), p.tz()));
}

}  // namespace plx

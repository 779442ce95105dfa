// SE3 <-> plenoxd.v1.Pose: the one conversion the daemon, the plenox CLI and the tests use, so
// that every pose on the wire follows one convention: a unit quaternion with qw >= 0 (q and -q
// are the same rotation; fixing the sign makes equal poses equal messages, as in the TUM files
// core/io writes). clients/python/plenoxd_client/convert.py applies the same rule.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"
#include "plenoxd/v1/plenoxd.pb.h"

namespace plx {

// Writes `pose` to `out`: the quaternion normalised, then negated when qw < 0.
void PoseToProto(const SE3& pose, ::plenoxd::v1::Pose* out);

// The pose of a message, its quaternion normalised. InvalidArgument naming the component
// ("<field>.qw: not finite") when one is not finite, or "<field>: the quaternion is zero".
absl::StatusOr<SE3> PoseFromProto(const ::plenoxd::v1::Pose& pose, const std::string& field);

}  // namespace plx

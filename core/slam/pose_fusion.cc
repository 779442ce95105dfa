#include "core/slam/pose_fusion.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx {

const char* PoseSourceName(PoseSource source) {
  switch (source) {
    case PoseSource::kMap: return "map";
    case PoseSource::kOdometry: return "odometry";
    case PoseSource::kPrediction: return "prediction";
  }
  return "?";
}

namespace {

bool WithinTolerance(const SE3& a, const SE3& b, double translation_m, double rotation_rad) {
  return (a.translation() - b.translation()).norm() <= translation_m &&
         RotationAngleBetween(a, b) <= rotation_rad;
}

}  // namespace

bool PosesAgree(const SE3& a, const SE3& b, const PoseFusionOptions& options) {
  return WithinTolerance(a, b, options.agree_translation_m, options.agree_rotation_rad);
}

CheckedPose ApplyFeatureCheck(const FusedPose& fused, bool features_found,
                              bool features_agree) {
  CheckedPose out{fused.state, fused.may_be_keyframe, fused.reason};
  const bool agree = features_found && features_agree;
  if (fused.confirm) {
    out.may_be_keyframe = agree;
    out.unconfirmed = !agree;
    if (agree) {
      absl::StrAppend(&out.reason, "; the keyframes' features confirm the map's pose");
    } else {
      out.state = SlamState::kDegraded;
      absl::StrAppend(&out.reason, features_found ? "; the keyframes' features place the frame "
                                                    "elsewhere, the map does not"
                                                  : "; the keyframes' features do not confirm "
                                                    "the map's pose");
    }
    return out;
  }
  if (agree) {
    out.may_be_keyframe = true;
    absl::StrAppend(&out.reason, "; the keyframes' features confirm it");
  }
  return out;
}

FusedPose ChainedToUnconfirmedPose(FusedPose fused) {
  if (fused.state == SlamState::kLost || fused.confirm) return fused;
  fused.confirm = true;
  fused.may_be_keyframe = false;
  const char* why = "the pose follows from one the keyframes' features did not confirm";
  fused.reason = fused.reason.empty() ? why : absl::StrCat(fused.reason, "; ", why);
  return fused;
}

FusedPose FusePoses(const TrackingResult& map, const std::optional<OdometryPose>& odometry,
                    const PoseFusionOptions& options) {
  FusedPose out;
  const bool odometry_ok = odometry && odometry->ok;
  if (map.state == TrackingState::kOk && odometry_ok &&
      !WithinTolerance(map.pose, odometry->pose, options.max_map_jump_m,
                       options.max_map_jump_rad)) {
    out.pose = odometry->pose;
    out.state = SlamState::kDegraded;
    out.source = PoseSource::kOdometry;
    out.reason = absl::StrFormat(
        "the map's pose jumped %.2f m / %.1f deg from the odometry's; pose from odometry",
        (map.pose.translation() - odometry->pose.translation()).norm(),
        RotationAngleBetween(map.pose, odometry->pose) * 180.0 / M_PI);
    return out;
  }
  if (map.state == TrackingState::kOk) {
    out.pose = map.pose;
    out.state = SlamState::kOk;
    out.source = PoseSource::kMap;
    // After a jump in the stream the map tracker may converge far from its start on a view it
    // explains well enough (a kidnap tracked OK at a wrong place, 0.5 m off, in the tests);
    // as a keyframe that pose would corrupt the map.
    out.confirm = odometry && !odometry->ok;
    out.may_be_keyframe = !out.confirm;
    if (out.confirm) out.reason = absl::StrCat("odometry: ", odometry->reason);
    return out;
  }
  if (!odometry_ok) {
    out.pose = map.pose;
    out.reason = map.reason;
    if (odometry && !odometry->reason.empty()) {
      absl::StrAppend(&out.reason, "; odometry: ", odometry->reason);
    }
    out.state = map.state == TrackingState::kLost ? SlamState::kLost : SlamState::kDegraded;
    out.source = map.state == TrackingState::kLost ? PoseSource::kPrediction : PoseSource::kMap;
    return out;
  }
  out.state = SlamState::kDegraded;
  if (map.cause == TrackingCause::kFewValidRays) {
    // Unmapped space, a sure pose: what a keyframe is for.
    out.may_be_keyframe = true;
    const bool agrees = map.state == TrackingState::kDegraded &&
                        PosesAgree(odometry->pose, map.pose, options);
    if (agrees) {
      out.pose = map.pose;
      out.source = PoseSource::kMap;
      out.reason = absl::StrCat(map.reason, " (the odometry agrees)");
      return out;
    }
    out.pose = odometry->pose;
    out.source = PoseSource::kOdometry;
    out.reason = absl::StrCat(map.reason, "; pose from odometry");
    return out;
  }
  // The map renders the view but does not explain the frame (or the estimate ran off): the
  // odometry's pose, and nothing of this frame goes into the map.
  out.pose = odometry->pose;
  out.source = PoseSource::kOdometry;
  out.reason = absl::StrCat(map.reason, "; pose from odometry");
  return out;
}

}  // namespace plx

#include "core/slam/keyframe_policy.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx {

absl::Status ValidateKeyframePolicy(const KeyframePolicy& p) {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(p.max_translation_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe max_translation_m must be positive, got ", p.max_translation_m));
  }
  if (!positive(p.max_rotation_rad)) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe max_rotation_rad must be positive, got ", p.max_rotation_rad));
  }
  if (!(p.max_unmapped_fraction > 0.0 && p.max_unmapped_fraction <= 1.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "keyframe max_unmapped_fraction must be in (0, 1], got ", p.max_unmapped_fraction));
  }
  if (!(std::isfinite(p.max_interval_s) && p.max_interval_s >= 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe max_interval_s must not be negative, got ", p.max_interval_s));
  }
  return absl::OkStatus();
}

KeyframeDecision DecideKeyframe(const KeyframePolicy& p,
                                const std::vector<StampedPose>& keyframes, const SE3& pose,
                                double time, double unmapped_fraction) {
  KeyframeDecision d;
  if (keyframes.empty()) {
    d.keyframe = true;
    d.reason = "first keyframe";
    return d;
  }
  // The nearest keyframe by translation among those within the rotation limit: the view is
  // covered when it is also within the translation limit.
  double nearest = HUGE_VAL, nearest_turn = HUGE_VAL;
  for (const StampedPose& k : keyframes) {
    const double moved = (pose.translation() - k.pose.translation()).norm();
    const double turned = RotationAngleBetween(k.pose, pose);
    if (turned <= p.max_rotation_rad && moved < nearest) nearest = moved;
    nearest_turn = std::min(nearest_turn, turned);
  }
  if (nearest_turn > p.max_rotation_rad) {
    d.reason = absl::StrFormat("turned %.1f deg from every keyframe", nearest_turn * 180.0 / M_PI);
  } else if (nearest > p.max_translation_m) {
    // Only keyframes that look the same way count (a view's coverage), so the distance can be
    // metres where keyframes nearby face elsewhere: the reason says so.
    d.reason = absl::StrFormat("%.3f m from every keyframe facing within %.0f deg", nearest,
                               p.max_rotation_rad * 180.0 / M_PI);
  } else if (unmapped_fraction > p.max_unmapped_fraction) {
    d.reason = absl::StrFormat("%.0f%% of the view unmapped", 100.0 * unmapped_fraction);
  } else if (p.max_interval_s > 0.0 && time - keyframes.back().timestamp > p.max_interval_s) {
    d.reason = absl::StrFormat("%.1f s since the last keyframe", time - keyframes.back().timestamp);
  }
  d.keyframe = !d.reason.empty();
  return d;
}

}  // namespace plx

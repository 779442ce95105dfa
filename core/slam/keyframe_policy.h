// When a tracked frame becomes a keyframe (DESIGN.md §9). A keyframe costs memory (its images
// are kept for mapping) and mapping time (its bricks are allocated and fused), so frames are
// taken only when they bring something the map lacks:
//   - the view is new: no keyframe is both within max_translation_m and within
//     max_rotation_rad of the frame (measured against every keyframe, not just the last, so a
//     camera that comes back to a place it has mapped adds nothing: memory follows the space
//     covered, not the length of the sequence);
//   - a large part of the frame is not rendered by the map (new space came into view);
//   - optionally, too long passed since the last keyframe (off by default: in a static scene
//     time alone brings nothing new).
// Only frames tracked OK qualify: a keyframe at a doubtful pose would write its error into the
// map.
#pragma once

#include <string>

#include "absl/status/status.h"
#include <vector>

#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"

namespace plx {

struct KeyframePolicy {
  double max_translation_m = 0.10;  // camera centre moved this far from the last keyframe's
  double max_rotation_rad = 0.26;   // ~15 degrees of rotation since the last keyframe
  // Fraction of the tracking rays (pixels with valid depth) the map does not render: new
  // space in view. Tracking needs most of the frame mapped, so this comes well before LOST.
  double max_unmapped_fraction = 0.15;
  double max_interval_s = 0.0;      // seconds since the last keyframe (0 = no time rule)
};

// InvalidArgument naming the field unless every threshold is finite and positive (the
// interval may be 0) and the fraction is in (0, 1].
absl::Status ValidateKeyframePolicy(const KeyframePolicy& policy);

struct KeyframeDecision {
  bool keyframe = false;
  std::string reason;  // which rule fired, e.g. "moved 0.12 m"; empty when not a keyframe
};

// `keyframes`: the poses of the keyframes so far (the last one is the most recent; at least
// one). `unmapped_fraction` = 1 - valid rays / rays of the frame's tracking result.
KeyframeDecision DecideKeyframe(const KeyframePolicy& policy,
                                const std::vector<StampedPose>& keyframes, const SE3& pose,
                                double time, double unmapped_fraction);

}  // namespace plx

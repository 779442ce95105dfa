#include "core/slam/keyframe_refinement.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace plx {

absl::Status ValidateKeyframeRefinementOptions(const KeyframeRefinementOptions& o) {
  if (o.window < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("refinement window must not be negative, got ", o.window));
  }
  if (!(o.max_translation_m > 0.0) || !(o.max_rotation_rad > 0.0) ||
      !std::isfinite(o.max_translation_m) || !std::isfinite(o.max_rotation_rad)) {
    return absl::InvalidArgumentError("refinement correction limits must be positive");
  }
  return Tracker::ValidateOptions(o.tracker);
}

absl::StatusOr<KeyframeRefinementResult> RefineKeyframePoses(
    MappingSession& session, const PlenoxelMap& map, Backend& backend,
    const KeyframeRefinementOptions& options) {
  const int n = session.keyframes().num_frames();
  std::vector<int> window;
  for (int i = std::max(1, n - options.window); i < n; ++i) window.push_back(i);
  return RefineKeyframeList(session, map, backend, options, window);
}

absl::StatusOr<KeyframeRefinementResult> RefineKeyframeList(
    MappingSession& session, const PlenoxelMap& map, Backend& backend,
    const KeyframeRefinementOptions& options, const std::vector<int>& indices) {
  KeyframeRefinementResult result;
  const TrainingSet& keyframes = session.keyframes();
  const int n = keyframes.num_frames();
  TrackerOptions tracker_options = options.tracker;
  tracker_options.constant_velocity = false;  // each keyframe starts from its own pose
  for (const int i : indices) {
    if (i < 1 || i >= n) continue;
    const SE3 pose = keyframes.pose(i);
    const RgbdFrame& frame = keyframes.frame(i);
    Tracker tracker(&map, &backend, tracker_options);
    tracker.Reset(pose, frame.timestamp);
    PLX_ASSIGN_OR_RETURN(TrackingResult aligned,
                         tracker.Track(frame, keyframes.intrinsics(i), pose));
    const double shift = (aligned.pose.translation() - pose.translation()).norm();
    const double turn = RotationAngleBetween(pose, aligned.pose);
    if (aligned.state != TrackingState::kOk || shift > options.max_translation_m ||
        turn > options.max_rotation_rad) {
      ++result.skipped;
      continue;
    }
    PLX_RETURN_IF_ERROR(session.SetKeyframePose(i, aligned.pose));
    ++result.refined;
    result.max_shift_m = std::max(result.max_shift_m, shift);
  }
  return result;
}

}  // namespace plx

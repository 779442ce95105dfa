// Keyframe pose refinement, SLAM's local bundle adjustment (DESIGN.md §9). The gradient of the
// rendering loss with respect to a keyframe's pose is the tracking Jacobian (DESIGN.md §8), so
// the keyframes of the recent window are re-aligned to the current map with the tracker's
// Gauss-Newton, and the map is then optimised at the refined poses: block-coordinate descent
// on the joint loss over (window poses, map), alternating with the mapping steps. Keyframe 0
// stays fixed: it anchors the map's frame (the gauge).
#pragma once

#include <vector>

#include "absl/status/statusor.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapping_session.h"
#include "core/tracking/tracker.h"

namespace plx {

struct KeyframeRefinementOptions {
  int window = 5;  // the last `window` keyframes (keyframe 0 excluded); 0 = off
  TrackerOptions tracker;
  // A correction larger than this is not a refinement but a failed alignment: it is skipped.
  double max_translation_m = 0.05;
  double max_rotation_rad = 0.05;
};

absl::Status ValidateKeyframeRefinementOptions(const KeyframeRefinementOptions& options);

struct KeyframeRefinementResult {
  int refined = 0;           // keyframes moved
  int skipped = 0;           // aligned but not OK, or moved too far
  double max_shift_m = 0.0;  // largest translation applied
};

// Aligns each keyframe of the window to `map` (a published version of `session`'s map) and
// moves it in `session`. Call from the session's step-runner thread.
absl::StatusOr<KeyframeRefinementResult> RefineKeyframePoses(
    MappingSession& session, const PlenoxelMap& map, Backend& backend,
    const KeyframeRefinementOptions& options);

// The same for the keyframes `indices` (keyframe 0, the gauge, is skipped; options.window is
// not read).
absl::StatusOr<KeyframeRefinementResult> RefineKeyframeList(
    MappingSession& session, const PlenoxelMap& map, Backend& backend,
    const KeyframeRefinementOptions& options, const std::vector<int>& indices);

}  // namespace plx

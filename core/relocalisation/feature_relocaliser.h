// A pose for a frame from the map's keyframes alone, wherever the camera is (docs/SLAM.md,
// "Relocalisation"): the keyframes whose thumbnails look most like the frame (place
// recognition) have their ORB descriptors matched against the frame's (mutual best, Lowe's
// ratio test), and each keyframe's matched 3D points (its depth, moved into the world by its
// refined pose) with the frame's pixels give a pose by RANSAC PnP. The keyframe with the most
// inliers wins when it has enough; the caller verifies that pose densely against the map
// (SlamTracker) before it trusts it.
//
// The work is bounded by the options: one thumbnail comparison per keyframe (microseconds), then
// descriptor matching and PnP on at most `candidate_keyframes` of them, whatever the map's size.
// RANSAC's random samples come from a generator OpenCV seeds on every call, so a result depends
// on its inputs only, whatever thread runs it (the lock-step daemon and in-process SLAM stay
// bit-identical; tested).
#pragma once

#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/relocalisation/frame_features.h"

namespace plx {

struct FeatureRelocaliserOptions {
  int candidate_keyframes = 4;   // matched and tried per call, the most similar first
  float ratio = 0.8f;            // Lowe's test: best distance below this times the second's
  int max_distance = 64;         // Hamming bits (of 256) for a match at all
  int min_matches = 20;          // per keyframe, to try PnP
  int min_inliers = 15;          // for a pose
  // RANSAC: reprojection error for an inlier, in pixels of a 640-pixel-wide image (scaled with
  // the width), and its iterations.
  double inlier_pixels = 3.0;
  int ransac_iterations = 200;
};

absl::Status ValidateFeatureRelocaliserOptions(const FeatureRelocaliserOptions& options);

// A keyframe as the relocaliser sees it: its features and its (refined) world_T_camera.
struct RelocalisationKeyframe {
  const FrameFeatures* features = nullptr;
  SE3 pose;
};

struct FeatureRelocalisation {
  SE3 pose;            // the frame's world_T_camera
  int keyframe = -1;   // index into the keyframes given
  int matches = 0;     // with that keyframe
  int inliers = 0;     // of them, PnP's
};

// The keyframe indices in order of thumbnail similarity, at most `count`, none below
// `min_similarity` (a covered lens or a flat wall matches no place).
std::vector<int> RankKeyframes(const FrameFeatures& frame,
                               const std::vector<RelocalisationKeyframe>& keyframes, int count,
                               float min_similarity = 0.0f);

// Descriptor matches frame -> keyframe (index pairs), mutual best and passing the ratio test.
std::vector<std::pair<int, int>> MatchFeatures(const FrameFeatures& frame,
                                               const FrameFeatures& keyframe,
                                               const FeatureRelocaliserOptions& options);

// The best PnP pose over the most similar keyframes, or none when no keyframe gives
// `min_inliers`. `k` is the frame's intrinsics.
std::optional<FeatureRelocalisation> RelocaliseByFeatures(
    const FrameFeatures& frame, const std::vector<RelocalisationKeyframe>& keyframes,
    const PinholeIntrinsics& k, const FeatureRelocaliserOptions& options);

}  // namespace plx

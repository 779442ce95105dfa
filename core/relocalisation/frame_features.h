// What relocalisation knows of a frame (docs/SLAM.md, "Relocalisation"): ORB keypoints that have
// depth, as 3D points in the frame's camera with their binary descriptors, and a thumbnail of
// the whole image. Every keyframe keeps one (SlamCoordinator, beside its pose), so a lost camera
// can find itself anywhere in the map: the thumbnail ranks the keyframes cheaply (place
// recognition), the descriptors match the best few, and their 3D points with this frame's
// pixels give a pose by RANSAC PnP (core/relocalisation/feature_relocaliser.h).
//
// Kept apart from the map's radiance field on purpose: descriptors do not depend on how well
// the map renders, so they work from the first keyframe on and in views the map renders badly.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"

namespace plx {

struct FrameFeatureOptions {
  // ORB keypoints kept per frame (the strongest; only those with depth are detected).
  int max_features = 500;
  // Depth outside (min_depth, max_depth] is no measurement: a keypoint needs one.
  float min_depth = 0.1f;
  float max_depth = 10.0f;
  // The thumbnail is this wide (height in the image's aspect ratio): small enough that
  // comparing it against every keyframe costs microseconds, blurred enough that a few pixels
  // of motion barely change it.
  int thumbnail_width = 40;
};

absl::Status ValidateFrameFeatureOptions(const FrameFeatureOptions& options);

using OrbDescriptor = std::array<uint8_t, 32>;  // 256 binary tests

struct FrameFeatures {
  // One entry per keypoint: its pixel in this frame (DESIGN.md §4's convention: the centre of
  // pixel (u, v) is (u + 0.5, v + 0.5)), its point in this camera (metres), its descriptor.
  std::vector<Eigen::Vector2f> pixels;
  std::vector<Eigen::Vector3f> points;
  std::vector<OrbDescriptor> descriptors;
  // Luma, zero mean and unit norm (all zero for a flat image): the dot product of two is their
  // normalised cross-correlation.
  std::vector<float> thumbnail;
  int thumbnail_width = 0, thumbnail_height = 0;

  int size() const { return static_cast<int>(points.size()); }
};

// InvalidArgument when the frame's images do not match `k`. A frame without texture or depth
// gives no keypoints (not an error).
absl::StatusOr<FrameFeatures> ExtractFrameFeatures(const RgbdFrame& frame,
                                                   const PinholeIntrinsics& k,
                                                   const FrameFeatureOptions& options);

// Normalised cross-correlation of two thumbnails in [-1, 1]; -1 when their sizes differ.
float ThumbnailSimilarity(const FrameFeatures& a, const FrameFeatures& b);

}  // namespace plx

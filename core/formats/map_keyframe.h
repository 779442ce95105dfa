// A keyframe of a map as the map's file keeps it (core/formats/map_file.h, format version 2):
// where the camera was and what relocalisation and the keyframe policy need of its view, so
// that SLAM continuing a saved map finds cameras in it by its features, does not map its views
// again, and counts its keyframes on from there (SlamCoordinator::SeedSavedKeyframes).
//
// The keyframe's images are not kept. The grid already holds what they built, and everything a
// continuing SLAM session reads of an old keyframe is its pose and features: ~31 KB for a
// 640x480 keyframe with 500 keypoints, about half a brick (57 KB), where its PNG images would
// add ~0.5-1 MB (measured: docs/BENCHMARKS.md, "Snapshots and keyframes in map files"). What
// that leaves out: loop closure's dense check and a rebuild at corrected poses need the images,
// so loops are closed among the keyframes taken since the map was loaded, not to saved ones.
#pragma once

#include <memory>
#include <vector>

#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/relocalisation/frame_features.h"

namespace plx {

struct MapKeyframe {
  double timestamp = 0.0;  // the frame's own clock (seconds)
  SE3 pose;                // world_T_camera, as mapping refined it
  PinholeIntrinsics intrinsics;
  // Null: none were extracted (an Integrate stream's keyframe, or SLAM with feature
  // relocalisation off). Immutable once shared.
  std::shared_ptr<const FrameFeatures> features;
};

// A map's keyframes in the order it accepted them.
using MapKeyframes = std::vector<MapKeyframe>;

}  // namespace plx

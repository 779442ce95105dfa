// The image pyramid the map-free RGB-D odometry (core/odometry/rgbd_odometry.h) works on: per
// level, intensity and depth with their gradients and the level's intrinsics. A frame's pyramid
// is built once and serves twice: as the current frame (its points) and, on the next frame, as
// the reference (its images, sampled where those points land).
//
// Halving the size keeps the intrinsics exact: pixel centres sit at (u + 0.5, v + 0.5)
// (DESIGN.md §4), so a 2x2 block's centre is the continuous coordinate halved, and fx, fy, cx,
// cy simply halve.
#pragma once

#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"

namespace plx {

struct OdometryPyramidOptions {
  // The finest level kept is the first one at most this wide: the odometry only needs the
  // coarse levels (the map tracker refines at full resolution where the map covers the view),
  // and a 640x480 frame costs 4x less at 320x240.
  int max_width = 320;
  // Levels are halved until the next would be narrower than this.
  int min_width = 40;
  // Depth outside (min_depth, max_depth] is no measurement.
  float min_depth = 0.1f;
  float max_depth = 10.0f;
  // A 2x2 block's depth averages its valid values within this fraction of the nearest one, so
  // a block across an object's edge keeps the foreground instead of a point in mid-air.
  float depth_block_tolerance = 0.03f;
};

absl::Status ValidateOdometryPyramidOptions(const OdometryPyramidOptions& options);

// One level. Images are row-major, width * height. Gradients are central differences in
// intensity (or metres) per pixel; a depth gradient is 0 where the depth is not continuous
// across the neighbours (an edge or a hole), and the depth residual is not used there.
struct OdometryLevel {
  int width = 0, height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  std::vector<float> intensity;  // luma of linear RGB, [0, 1]
  std::vector<float> intensity_du, intensity_dv;
  std::vector<float> depth;      // metres, 0 = none
  std::vector<float> depth_du, depth_dv;
  std::vector<unsigned char> depth_smooth;  // 1 where depth and its gradient are usable
};

struct OdometryPyramid {
  std::vector<OdometryLevel> levels;  // [0] the finest kept, then coarser
  int64_t valid_depth = 0;            // at the finest kept level
};

// InvalidArgument when the frame's images do not match `k` or are empty.
absl::StatusOr<OdometryPyramid> BuildOdometryPyramid(const RgbdFrame& frame,
                                                     const PinholeIntrinsics& k,
                                                     const OdometryPyramidOptions& options);

}  // namespace plx

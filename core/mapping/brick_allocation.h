// Depth-guided allocation (DESIGN.md §5): the bricks a keyframe's measured surfaces need.
#pragma once

#include <vector>

#include "core/geometry/image.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/grid/sparse_grid.h"
#include "core/math/depth_noise.h"

namespace plx {

struct AllocationOptions {
  // Metres in front of and behind each measured point along its ray:
  // max(min_band, band_sigmas * noise.Sigma(z)).
  float min_band = 0.08f;
  float band_sigmas = 3.0f;
  DepthNoiseModel noise;
  float max_depth = 10.0f; // measurements beyond this are ignored
  int pixel_stride = 2;    // every n-th pixel per row and column
};

// Bricks (of a grid with `voxel_size`) crossed by the segment [d - band, d + band] along the ray
// of every sampled pixel with measured depth d. Unique, in no particular order. Points outside
// the world extent (core/common/world_extent.h) are left out.
std::vector<BrickCoord> BricksNearSurface(const DepthImage& depth, const SE3& world_T_camera,
                                          const PinholeIntrinsics& intrinsics, float voxel_size,
                                          const AllocationOptions& options);

}  // namespace plx

#include "core/mapping/brick_allocation.h"

#include <cmath>

#include "absl/container/flat_hash_set.h"
#include "core/common/world_extent.h"
#include "core/grid/grid_view.h"

namespace plx {

std::vector<BrickCoord> BricksNearSurface(const DepthImage& depth, const SE3& world_T_camera,
                                          const PinholeIntrinsics& k, float voxel_size,
                                          const AllocationOptions& options) {
  absl::flat_hash_set<BrickCoord> bricks;
  const Eigen::Matrix3d R = world_T_camera.rotation_matrix();
  const Eigen::Vector3d origin = world_T_camera.translation();
  const double brick_size = static_cast<double>(voxel_size) * kBrickEdge;
  // Half a voxel between points on the segment: no brick the segment crosses is skipped by more
  // than a sliver.
  const double step = 0.5 * voxel_size;
  const int stride = std::max(1, options.pixel_stride);
  for (int v = 0; v < depth.height; v += stride) {
    for (int u = 0; u < depth.width; u += stride) {
      const float z = *depth.pixel(u, v);
      if (!(z > 0.0f) || z > options.max_depth) continue;
      const Eigen::Vector3d dc((u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy, 1.0);
      const double range = z * dc.norm();
      const Eigen::Vector3d dir = R * dc.normalized();
      const double band = std::max(options.min_band, options.band_sigmas * options.noise.Sigma(z));
      const double t0 = std::max(0.0, range - band), t1 = range + band;
      BrickCoord last{INT32_MIN, INT32_MIN, INT32_MIN};
      for (double t = t0; t <= t1; t += step) {
        const Eigen::Vector3d p = origin + t * dir;
        // Points past the world extent are not mapped (converting their brick coordinates to
        // int32 could wrap around); every brick below is inside SparseGrid::WorldBrickRange.
        if (!(p.cwiseAbs().maxCoeff() <= kWorldExtentMeters)) continue;
        const BrickCoord b{static_cast<int32_t>(std::floor(p.x() / brick_size)),
                           static_cast<int32_t>(std::floor(p.y() / brick_size)),
                           static_cast<int32_t>(std::floor(p.z() / brick_size))};
        if (b == last) continue;
        bricks.insert(b);
        last = b;
      }
    }
  }
  return std::vector<BrickCoord>(bricks.begin(), bricks.end());
}

}  // namespace plx

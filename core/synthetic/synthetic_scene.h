// The procedural indoor room behind the synthetic RGB-D sequences: a closed box-shaped room
// with a few boxes standing on the floor, every surface carrying a smooth procedural texture.
// Everything is analytic (planes and oriented boxes), so any view at any pose can be ray-cast
// exactly; tests and evaluation use this to make held-out views and exact ground truth.
//
// World frame: z up, floor at z = 0, the room centred on the origin in x and y. Units: metres.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"

namespace plx {

// A box standing on the floor (or on another box), rotated about the world z axis.
struct SyntheticBox {
  Eigen::Vector3d center;        // world coordinates of the box centre
  Eigen::Vector3d half_extents;  // half sizes along the box's own x, y, z axes
  double yaw = 0.0;              // rotation about world +z, radians (box x axis = (cos, sin, 0))
};

struct SyntheticScene {
  Eigen::Vector3d room_min;  // inner faces of the floor and the walls at -x, -y
  Eigen::Vector3d room_max;  // inner faces of the ceiling and the walls at +x, +y
  std::vector<SyntheticBox> boxes;
};

// The one fixed scene: a 6 m (x) x 5 m (y) x 3 m (z) room, x in [-3, 3], y in [-2.5, 2.5],
// z in [0, 3], with a table-height box, a tall cabinet, a crate with a small cube on top and a
// medium box near the walls.
const SyntheticScene& SyntheticRoom();

// Surface ids of SyntheticHit: the room's six faces, then box i as kSyntheticFirstBox + i.
enum SyntheticSurface : int {
  kSyntheticNoHit = -1,
  kSyntheticFloor = 0,
  kSyntheticCeiling = 1,
  kSyntheticWallMinX = 2,
  kSyntheticWallMaxX = 3,
  kSyntheticWallMinY = 4,
  kSyntheticWallMaxY = 5,
  kSyntheticFirstBox = 6,
};

struct SyntheticHit {
  double t = 0.0;  // hit point = origin + t * direction (direction as passed, not normalised)
  int surface = kSyntheticNoHit;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // world
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, facing the ray origin
};

// Nearest surface along origin + t * direction, t > 0. `origin` must lie inside the room and
// outside every box (all views of the room do); surface is kSyntheticNoHit otherwise.
SyntheticHit CastSyntheticRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction);

// Linear RGB in [0, 1] of a hit: procedural albedo times a fixed diffuse shading per face
// (view independent, so every view of a point agrees).
Eigen::Vector3f SyntheticSurfaceColor(const SyntheticHit& hit);

// Noise-free view of the scene at any pose and pinhole camera. Depth is the exact z-depth of
// the ray through each pixel centre; colour averages supersampling x supersampling rays per
// pixel (anti-aliasing; clamped to 1..4). The pose becomes the frame's ground_truth, the
// timestamp is 0. Rows are split over threads. Non-positive sizes give empty images.
RgbdFrame RenderSyntheticView(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics,
                              int supersampling = 2);

namespace internal {
// Renders rows [row_begin, row_end) of `frame` (already sized) on the calling thread.
void RenderSyntheticRows(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics,
                         int supersampling, int row_begin, int row_end, RgbdFrame* frame);
}  // namespace internal

}  // namespace plx

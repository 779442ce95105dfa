// The procedural indoor scenes behind the synthetic RGB-D sequences: a closed box-shaped room
// with a few boxes standing on the floor, every surface carrying a smooth procedural texture,
// and two such rooms side by side joined by a doorway. Everything is analytic (planes and
// oriented boxes), so any view at any pose can be ray-cast exactly; tests and evaluation use
// this to make held-out views and exact ground truth.
//
// World frame: z up, floor at z = 0, the scene centred on the origin in x and y. Units: metres.
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

enum class SyntheticSceneKind {
  // A 6 m (x) x 5 m (y) x 3 m (z) room, x in [-3, 3], y in [-2.5, 2.5], z in [0, 3], with a
  // table-height box, a tall cabinet, a crate with a small cube on top and a medium box near
  // the walls.
  kRoom,
  // 12 m x 5 m x 3 m (x in [-6, 6]) split at x = 0 by a 20 cm partition with a doorway 1.6 m
  // wide and 2.1 m high at y in [-0.8, 0.8] (the partition and the lintel are boxes). The -x
  // room holds kRoom's boxes moved 3 m towards -x; the +x room is furnished differently (a
  // long low box with a cushion on it, a tall shelf, a dresser and a stool), so the two rooms
  // share walls, floor and ceiling textures but not their furniture: a walk through both is
  // a loop through places that look alike in part (issue 22's two-room data).
  kTwoRooms,
};

// The scene's geometry (built once, immutable).
const SyntheticScene& SyntheticSceneOf(SyntheticSceneKind kind);

// SyntheticSceneOf(SyntheticSceneKind::kRoom): the scene of every path but the two-room one.
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

// Nearest surface of `scene` along origin + t * direction, t > 0. `origin` must lie inside the
// room and outside every box (all views of the scene do); surface is kSyntheticNoHit otherwise.
SyntheticHit CastSyntheticRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                              SyntheticSceneKind scene = SyntheticSceneKind::kRoom);

// Linear RGB in [0, 1] of a hit in `scene`: procedural albedo times a fixed diffuse shading per
// face (view independent, so every view of a point agrees).
Eigen::Vector3f SyntheticSurfaceColor(const SyntheticHit& hit,
                                      SyntheticSceneKind scene = SyntheticSceneKind::kRoom);

// Noise-free view of `scene` at any pose and pinhole camera. Depth is the exact z-depth of the
// ray through each pixel centre; colour averages supersampling x supersampling rays per pixel
// (anti-aliasing; clamped to 1..4). The pose becomes the frame's ground_truth, the timestamp
// is 0. Rows are split over threads. Non-positive sizes give empty images.
RgbdFrame RenderSyntheticView(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics,
                              int supersampling = 2,
                              SyntheticSceneKind scene = SyntheticSceneKind::kRoom);

namespace internal {
// Renders rows [row_begin, row_end) of `frame` (already sized) on the calling thread.
void RenderSyntheticRows(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics,
                         int supersampling, SyntheticSceneKind scene, int row_begin,
                         int row_end, RgbdFrame* frame);
}  // namespace internal

}  // namespace plx

// Distance from a point to the nearest analytic surface of the synthetic room
// (core/synthetic/synthetic_scene.h: the room's six faces and its boxes), for tests that
// compare geometry made from the room's views with the truth.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "core/synthetic/synthetic_scene.h"

namespace plx::testing {

// Distance from q to the surface of the axis-aligned box [-half, half] (inside or outside).
inline double BoxSurfaceDistance(const Eigen::Vector3d& q, const Eigen::Vector3d& half) {
  const Eigen::Vector3d excess = q.cwiseAbs() - half;
  if ((excess.array() <= 0.0).all()) return -excess.maxCoeff();
  return excess.cwiseMax(0.0).norm();
}

// p in the frame of `box` (its centre, rotated by -yaw about z).
inline Eigen::Vector3d InBoxFrame(const SyntheticBox& box, const Eigen::Vector3d& p) {
  const Eigen::Vector3d d = p - box.center;
  const double c = std::cos(box.yaw), s = std::sin(box.yaw);
  return {c * d.x() + s * d.y(), -s * d.x() + c * d.y(), d.z()};
}

// Signed distance from p to the surface of `box` (negative inside).
inline double SignedDistanceToBox(const SyntheticBox& box, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = InBoxFrame(box, p).cwiseAbs() - box.half_extents;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

inline double DistanceToSyntheticRoom(const Eigen::Vector3d& p) {
  const SyntheticScene& scene = SyntheticRoom();
  const Eigen::Vector3d center = 0.5 * (scene.room_min + scene.room_max);
  double best = BoxSurfaceDistance(p - center, 0.5 * (scene.room_max - scene.room_min));
  for (const SyntheticBox& box : scene.boxes) {
    best = std::min(best, BoxSurfaceDistance(InBoxFrame(box, p), box.half_extents));
  }
  return best;
}

}  // namespace plx::testing

// Derivatives with respect to a camera pose under the right perturbation
// world_T_camera * Exp(xi), xi = [rho; phi] (DESIGN.md §4, §8). For a point q fixed in the
// camera frame, p = R q + t moves as dp/dxi = R [ I | -[q]x ]; a camera-frame direction d_c
// turns as dd/dxi = [ 0 | -R [d_c]x ].
#pragma once

#include "core/common/host_device.h"
#include "core/math/rigid_transform.h"
#include "core/math/vec3.h"

namespace plx {

// Returns g^T dp/dxi for a world-space row vector g (the derivative of some scalar w.r.t. p)
// and the camera-frame point q: [ R^T g ; q x (R^T g) ].
template <typename T>
PLX_HD void PointGradientToPose(const RigidTransform<T>& world_T_camera, const Vec3<T>& q,
                                const Vec3<T>& g_world, T out[6]) {
  const RigidTransform<T>& X = world_T_camera;
  // R^T g.
  const Vec3<T> g{X.r[0] * g_world.x + X.r[3] * g_world.y + X.r[6] * g_world.z,
                  X.r[1] * g_world.x + X.r[4] * g_world.y + X.r[7] * g_world.z,
                  X.r[2] * g_world.x + X.r[5] * g_world.y + X.r[8] * g_world.z};
  // g^T R (-[q]x) phi = (R^T g) . (phi x q) = phi . (q x R^T g).
  const Vec3<T> rot = Cross(q, g);
  out[0] = g.x;
  out[1] = g.y;
  out[2] = g.z;
  out[3] = rot.x;
  out[4] = rot.y;
  out[5] = rot.z;
}

// Returns g^T dd/dxi for a world-space direction gradient g and the camera-frame direction
// d_c: [ 0 ; d_c x (R^T g) ].
template <typename T>
PLX_HD void DirectionGradientToPose(const RigidTransform<T>& world_T_camera, const Vec3<T>& d_c,
                                    const Vec3<T>& g_world, T out[6]) {
  PointGradientToPose(world_T_camera, d_c, g_world, out);
  out[0] = out[1] = out[2] = T(0);
}

}  // namespace plx

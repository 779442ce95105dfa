// Walks the sample lattice t_k = k * step of one ray through the brick grid, jumping over
// blocks whose cells touch no stored vertex (empty-space skipping, DESIGN.md §5). Samples sit
// at fixed multiples of `step` from the ray origin, so a sample's distance does not depend on
// where the ray enters the grid (the "fixed t" of the tracking Jacobians, DESIGN.md §8).
// Forward, backward and tracking passes all walk rays through this one function, so they visit
// identical samples.
#pragma once

#include <cmath>

#include "core/common/host_device.h"
#include "core/grid/grid_sample.h"
#include "core/grid/grid_view.h"
#include "core/math/vec3.h"

namespace plx {

// Clips [*t0, *t1] to the part of the ray o + t d (grid coordinates) inside the axis-aligned box
// [lo, hi]^3 per axis; returns false when nothing is left.
template <typename T>
PLX_HD bool ClipRayToBox(const Vec3<T>& o, const Vec3<T>& d, const T lo[3], const T hi[3], T* t0,
                         T* t1) {
  for (int a = 0; a < 3; ++a) {
    const T oa = o[a], da = d[a];
    if (fabs(da) < T(1e-12)) {
      if (oa < lo[a] || oa > hi[a]) return false;
      continue;
    }
    const T inv = T(1) / da;
    T ta = (lo[a] - oa) * inv, tb = (hi[a] - oa) * inv;
    if (ta > tb) {
      const T tmp = ta;
      ta = tb;
      tb = tmp;
    }
    *t0 = ta > *t0 ? ta : *t0;
    *t1 = tb < *t1 ? tb : *t1;
  }
  return *t0 <= *t1;
}

// Calls visit(t, sample) for every lattice sample in [t_near, t_far] whose cell is marked
// occupied (see GridViewT::cell_bits), in increasing t, until visit returns false. `origin` and
// `dir` are in world units (dir need not be unit; t is measured in multiples of |dir|).
template <typename T, typename Visitor>
PLX_HD void MarchRay(const GridViewT<T>& grid, const Vec3<T>& origin, const Vec3<T>& dir, T t_near,
                     T t_far, T step, Visitor&& visit) {
  const Vec3<T> go = grid.ToGrid(origin);
  const T inv_voxel = T(1) / grid.voxel_size;
  const Vec3<T> gd = dir * inv_voxel;
  const T lo[3] = {T(0), T(0), T(0)};
  const T hi[3] = {T(grid.vertex_extent(0) - 1), T(grid.vertex_extent(1) - 1),
                   T(grid.vertex_extent(2) - 1)};
  T t0 = t_near, t1 = t_far;
  if (!ClipRayToBox(go, gd, lo, hi, &t0, &t1)) return;

  int64_t k = static_cast<int64_t>(ceil(t0 / step));
  const int64_t k_end = static_cast<int64_t>(floor(t1 / step));
  CellSample<T> sample;
  while (k <= k_end) {
    const T t = T(k) * step;
    const Vec3<T> q = go + gd * t;
    const int cx = static_cast<int>(floor(q.x)), cy = static_cast<int>(floor(q.y)),
              cz = static_cast<int>(floor(q.z));
    const int bx = cx >> kBrickShift, by = cy >> kBrickShift, bz = cz >> kBrickShift;
    const int32_t bits = grid.BlockCells(bx, by, bz);
    if (bits < 0) {
      // Leave the block: the nearest exit plane along each moving axis.
      T t_exit = t1;
      const int b[3] = {bx, by, bz};
      for (int a = 0; a < 3; ++a) {
        const T da = gd[a];
        if (fabs(da) < T(1e-12)) continue;
        const T plane = T((da > 0 ? b[a] + 1 : b[a]) * kBrickEdge);
        const T ta = (plane - go[a]) / da;
        t_exit = ta < t_exit ? ta : t_exit;
      }
      const int64_t k_exit = static_cast<int64_t>(floor(t_exit / step)) + 1;
      k = k_exit > k + 1 ? k_exit : k + 1;
      continue;
    }
    if (!grid.CellOccupied(bits, cx & (kBrickEdge - 1), cy & (kBrickEdge - 1),
                           cz & (kBrickEdge - 1))) {
      ++k;  // every corner is empty: the sample would be skipped by the density threshold
      continue;
    }
    LocateCell(grid, q, &sample);
    if (!visit(t, sample)) return;
    ++k;
  }
}

}  // namespace plx

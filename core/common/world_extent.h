// The part of the world a map may cover: every pose the engine maps from and every brick a map
// stores lies within kWorldExtentMeters of the origin on each axis (docs/LIMITS.md).
//
// Why 10 km: positions reach the kernels as float32, whose spacing at 10^4 m is 2^-10 m (about
// 1 mm), the smallest voxel size a map may have and 1/20 of the default 2 cm voxel, so a ray
// marched anywhere inside the extent still resolves voxels. A larger extent would quantise
// positions more coarsely than the finest voxels (10^5 m: 8 mm). Brick coordinates are int32;
// at the finest voxels (1 mm, 8 mm bricks) the extent is 1.25 * 10^6 bricks, far from
// overflowing them or the int32 vertex coordinates (8 per brick) the grid computes. And 10 km
// covers any building, campus or street a session maps. Beyond it, a pose or a brick is an
// error, not something to wrap around or clamp.
#pragma once

#include <cmath>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace plx {

inline constexpr double kWorldExtentMeters = 1e4;

// OK when (x, y, z) is finite and within kWorldExtentMeters on every axis; otherwise
// InvalidArgument "<what>: ...", naming the coordinates and the extent.
inline absl::Status CheckInsideWorld(double x, double y, double z, absl::string_view what) {
  const double c[3] = {x, y, z};
  for (double v : c) {
    if (!(std::abs(v) <= kWorldExtentMeters)) {  // also rejects NaN
      return absl::InvalidArgumentError(absl::StrCat(
          what, ": (", x, ", ", y, ", ", z, ") m is outside the world extent of +-",
          kWorldExtentMeters, " m per axis"));
    }
  }
  return absl::OkStatus();
}

}  // namespace plx

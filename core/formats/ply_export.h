// The map as a coloured point cloud in binary little-endian PLY (x y z float, red green blue
// uchar): one point per stored vertex on the surface of the density field, i.e. with density
// above `min_density` and a face neighbour at or below it, coloured by its view-independent
// (DC) spherical-harmonic term.
#pragma once

#include <functional>
#include <string>

#include "absl/status/statusor.h"
#include "core/grid/plenoxel_map.h"

namespace plx {

struct PlyExport {
  std::string bytes;
  int64_t points = 0;
};

// The density threshold when the caller names none: the daemon's Export with min_density 0,
// and what `plenox export --help` promises for it.
inline constexpr float kDefaultExportMinDensity = 5.0f;

// `cancelled` is asked every few thousand vertices; true stops the export with CANCELLED (the
// caller gave up). Out of memory is RESOURCE_EXHAUSTED.
absl::StatusOr<PlyExport> ExportSurfacePointsPly(
    const PlenoxelMap& map, float min_density,
    const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

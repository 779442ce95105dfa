#include "core/formats/ply_export.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/formats/ply_binary.h"
#include "core/math/spherical_harmonics.h"

namespace plx {

absl::StatusOr<PlyExport> ExportSurfacePointsPly(const PlenoxelMap& map, float min_density,
                                                 const std::function<bool()>& cancelled) {
  return CatchAllocationFailure("exporting the map", [&]() -> absl::StatusOr<PlyExport> {
    const SparseGrid& grid = map.grid;
    const GridView view = grid.view();
    std::string body;
    int64_t points = 0;
    const float c0 = 0.28209479177387814f;
    for (int64_t vertex = 0; vertex < grid.num_vertices(); ++vertex) {
      // Every 8 bricks (4096 vertices): a large map takes seconds to export.
      if (cancelled && vertex % 4096 == 0 && cancelled()) {
        return absl::CancelledError("export cancelled");
      }
      if (!(view.Density(vertex) > min_density)) continue;
      int v[3];
      view.VertexCoords(vertex, v);
      bool surface = false;
      for (int axis = 0; axis < 3 && !surface; ++axis) {
        for (int step = -1; step <= 1 && !surface; step += 2) {
          int n[3] = {v[0], v[1], v[2]};
          n[axis] += step;
          const int64_t slot = view.VertexSlot(n[0], n[1], n[2]);
          surface = slot < 0 || !(view.Density(slot) > min_density);
        }
      }
      if (!surface) continue;
      const Vec3f p = view.VertexPosition(v[0], v[1], v[2]);
      ply::Append(&body, p.x);
      ply::Append(&body, p.y);
      ply::Append(&body, p.z);
      const float* sh = view.Sh(vertex);
      for (int c = 0; c < 3; ++c) {
        const float value = std::clamp(c0 * sh[c * kShBasisCount] + 0.5f, 0.0f, 1.0f);
        body.push_back(static_cast<char>(static_cast<uint8_t>(std::lround(value * 255.0f))));
      }
      ++points;
    }
    PlyExport out;
    out.points = points;
    out.bytes = absl::StrCat("ply\nformat binary_little_endian 1.0\n",
                             ply::SourceComment(map.source), "element vertex ", points,
                             "\nproperty float x\nproperty float y\nproperty float z\n"
                             "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                             "end_header\n");
    out.bytes += body;
    return out;
  });
}

}  // namespace plx

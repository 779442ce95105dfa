#include "core/render/render_view.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/refresh_occupancy.h"

namespace plx {

absl::StatusOr<RenderedPixels> RenderPixels(Backend& backend, const PlenoxelMap& map,
                                            const SE3& world_T_camera,
                                            const PinholeIntrinsics& intrinsics,
                                            const std::vector<int32_t>& pixels) {
  return CatchAllocationFailure("rendering", [&]() -> absl::StatusOr<RenderedPixels> {
  const int64_t n = pixels.empty() ? static_cast<int64_t>(intrinsics.width) * intrinsics.height
                                   : static_cast<int64_t>(pixels.size());
  RenderedPixels out;
  out.color.resize(3 * n);
  out.depth.resize(n);
  out.opacity.resize(n);
  out.median_depth.resize(n);
  if (map.grid.num_bricks() == 0) {
    // Nothing stored: every ray sees the background.
    for (int64_t i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) out.color[3 * i + c] = map.render.background[c];
    }
    return out;
  }
  // The caller's pixel list is ordinary host memory; a GPU backend reads the unified copy.
  const UnifiedVector<int32_t> pixel_ids(pixels.begin(), pixels.end());
  PLX_RETURN_IF_ERROR(backend.RenderPixels(
      map.grid.view(), ToKernelCamera(world_T_camera, intrinsics),
      pixel_ids.empty() ? nullptr : pixel_ids.data(), n, map.render, out.color.data(),
      out.depth.data(), out.opacity.data(), out.median_depth.data()));
  return out;
  });
}

absl::StatusOr<RenderedView> RenderView(Backend& backend, const PlenoxelMap& map,
                                        const SE3& world_T_camera, const PinholeIntrinsics& k,
                                        const RenderViewOptions& options) {
  return CatchAllocationFailure("rendering", [&]() -> absl::StatusOr<RenderedView> {
    RenderedView view;
    view.color = ColorImage(k.width, k.height, 3);
    view.z_depth = DepthImage(k.width, k.height, 1);
    view.opacity = Image<float>(k.width, k.height, 1);
    const int64_t width = std::max(k.width, 1);
    const int64_t rows = std::clamp<int64_t>(options.tile_pixels / width, 1, std::max(k.height, 1));
    const int rows_per_tile = static_cast<int>(rows);
    std::vector<int32_t> ids;
    for (int v0 = 0; v0 < k.height; v0 += rows_per_tile) {
      if (options.cancelled && options.cancelled()) {
        return absl::CancelledError(absl::StrCat("rendering cancelled after ", v0, " of ",
                                                 k.height, " rows"));
      }
      const int v1 = std::min(k.height, v0 + rows_per_tile);
      // Pixel ids of the tile's rows: the same rays, bit for bit, as one call over the view.
      ids.resize(static_cast<size_t>(v1 - v0) * k.width);
      for (size_t i = 0; i < ids.size(); ++i) {
        ids[i] = static_cast<int32_t>(int64_t{v0} * k.width + static_cast<int64_t>(i));
      }
      PLX_ASSIGN_OR_RETURN(const RenderedPixels px,
                           RenderPixels(backend, map, world_T_camera, k, ids));
      for (int v = v0; v < v1; ++v) {
        for (int u = 0; u < k.width; ++u) {
          const int64_t i = static_cast<int64_t>(v) * k.width + u;  // in the view
          const int64_t t = i - int64_t{v0} * k.width;               // in the tile
          for (int c = 0; c < 3; ++c) {
            view.color.data[3 * i + c] = std::clamp(px.color[3 * t + c], 0.0f, 1.0f);
          }
          const double x = (u + 0.5 - k.cx) / k.fx, y = (v + 0.5 - k.cy) / k.fy;
          view.z_depth.data[i] =
              static_cast<float>(px.RenderedRange(t) / std::sqrt(x * x + y * y + 1.0));
          view.opacity.data[i] = px.opacity[t];
        }
      }
    }
    return view;
  });
}

absl::Status CheckRenderPixels(const PinholeIntrinsics& k, int64_t max_pixels) {
  const int64_t pixels = int64_t{k.width} * k.height;
  if (pixels > max_pixels) {
    return absl::ResourceExhaustedError(absl::StrCat(k.width, " x ", k.height, " = ", pixels,
                                                     " pixels, over the limit of ", max_pixels,
                                                     " pixels per render"));
  }
  return absl::OkStatus();
}

}  // namespace plx

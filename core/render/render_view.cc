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

namespace {

// Sizes `image` for the view and reserves room for all its pixels without writing any: the
// reservation is address space, whose pages are touched only as tiles are stored. Zeroing a
// large view's images up front (1.3 GB for 8192^2) took seconds, all before the first
// cancellation check.
void ReserveImage(const PinholeIntrinsics& k, int channels, Image<float>* image) {
  image->width = k.width;
  image->height = k.height;
  image->channels = channels;
  image->data.reserve(static_cast<size_t>(k.width) * k.height * channels);
}

// Grows `image` to its first `rows` rows (within the reservation: nothing is moved).
void GrowImage(int rows, Image<float>* image) {
  image->data.resize(static_cast<size_t>(rows) * image->width * image->channels);
}

// Stores a tile's rendered pixels (rows v0 to v1) in the view, grown to hold them.
void StoreTile(const RenderedPixels& px, const PinholeIntrinsics& k, int v0, int v1,
               RenderedView* view) {
  GrowImage(v1, &view->color);
  GrowImage(v1, &view->z_depth);
  GrowImage(v1, &view->opacity);
  for (int v = v0; v < v1; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const int64_t i = static_cast<int64_t>(v) * k.width + u;  // in the view
      const int64_t t = i - int64_t{v0} * k.width;               // in the tile
      for (int c = 0; c < 3; ++c) {
        view->color.data[3 * i + c] = std::clamp(px.color[3 * t + c], 0.0f, 1.0f);
      }
      const double x = (u + 0.5 - k.cx) / k.fx, y = (v + 0.5 - k.cy) / k.fy;
      view->z_depth.data[i] =
          static_cast<float>(px.RenderedRange(t) / std::sqrt(x * x + y * y + 1.0));
      view->opacity.data[i] = px.opacity[t];
    }
  }
}

}  // namespace

absl::StatusOr<RenderedView> RenderView(Backend& backend, const PlenoxelMap& map,
                                        const SE3& world_T_camera, const PinholeIntrinsics& k,
                                        const RenderViewOptions& options) {
  return CatchAllocationFailure("rendering", [&]() -> absl::StatusOr<RenderedView> {
    RenderedView view;
    const int64_t width = std::max(k.width, 1);
    const int64_t rows = std::clamp<int64_t>(options.tile_pixels / width, 1, std::max(k.height, 1));
    const int rows_per_tile = static_cast<int>(rows);
    std::vector<int32_t> ids;
    for (int v0 = 0; v0 < k.height; v0 += rows_per_tile) {
      // Asked before anything is allocated, too: a call given up before it started costs
      // nothing.
      if (options.cancelled && options.cancelled()) {
        return absl::CancelledError(absl::StrCat("rendering cancelled after ", v0, " of ",
                                                 k.height, " rows"));
      }
      if (v0 == 0) {
        ReserveImage(k, 3, &view.color);
        ReserveImage(k, 1, &view.z_depth);
        ReserveImage(k, 1, &view.opacity);
      }
      const int v1 = std::min(k.height, v0 + rows_per_tile);
      // Pixel ids of the tile's rows: the same rays, bit for bit, as one call over the view.
      ids.resize(static_cast<size_t>(v1 - v0) * k.width);
      for (size_t i = 0; i < ids.size(); ++i) {
        ids[i] = static_cast<int32_t>(int64_t{v0} * k.width + static_cast<int64_t>(i));
      }
      PLX_ASSIGN_OR_RETURN(const RenderedPixels px,
                           RenderPixels(backend, map, world_T_camera, k, ids));
      StoreTile(px, k, v0, v1, &view);
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

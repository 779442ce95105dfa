// Rendering whole views or pixel subsets of a map from a camera pose, with the conversions
// users want (z-depth images, "did the map render anything here").
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "core/common/unified_allocator.h"
#include "core/geometry/image.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"

namespace plx {

// A pixel counts as rendered when the map's opacity along its ray reaches this.
inline constexpr float kRenderedOpacity = 0.5f;

// Written by the backend's kernels, hence UnifiedVector (core/common/unified_allocator.h).
struct RenderedPixels {
  UnifiedVector<float> color;    // [n * 3], unclamped
  UnifiedVector<float> depth;    // [n], expected range sum_i w_i t_i (not normalised)
  UnifiedVector<float> opacity;  // [n]
  UnifiedVector<float> median_depth;  // [n], range where the transmittance reaches 1/2

  // The surface range of pixel i, or 0 when the pixel is not rendered.
  float RenderedRange(int64_t i) const {
    return opacity[i] >= kRenderedOpacity ? median_depth[i] : 0.0f;
  }
};

// Renders the given pixel ids (v * width + u); all pixels in order when `pixels` is empty.
// `pixels` may be host memory (it is copied into a UnifiedVector for the backend). The map is
// only read (a published version; see Tracker for occupancy). Errors: the backend's.
absl::StatusOr<RenderedPixels> RenderPixels(Backend& backend, const PlenoxelMap& map,
                                            const SE3& world_T_camera,
                                            const PinholeIntrinsics& intrinsics,
                                            const std::vector<int32_t>& pixels = {});

struct RenderedView {
  ColorImage color;    // clamped to [0, 1]
  DepthImage z_depth;  // metres along the optical axis; 0 where nothing is rendered
  Image<float> opacity;
};

// How RenderView works through a view: in tiles of whole rows, asking between tiles whether
// the caller still wants the result, so a large view holds its device for at most one tile
// after its caller gave up (a gRPC deadline, a cancelled call) and keeps only one tile's
// per-ray buffers besides the images.
struct RenderViewOptions {
  // Pixels per tile, rounded down to whole rows (at least one row).
  int64_t tile_pixels = int64_t{1} << 18;
  // Asked before each tile; true stops the render with CANCELLED. Null: never.
  std::function<bool()> cancelled;
};

// Renders every pixel of the view. Errors: the backend's, CANCELLED (options.cancelled),
// RESOURCE_EXHAUSTED when out of memory.
absl::StatusOr<RenderedView> RenderView(Backend& backend, const PlenoxelMap& map,
                                        const SE3& world_T_camera,
                                        const PinholeIntrinsics& intrinsics,
                                        const RenderViewOptions& options = {});

// OK when a view of `intrinsics` has at most `max_pixels` pixels; otherwise RESOURCE_EXHAUSTED
// "W x H = N pixels, over the limit of M pixels per render". A server's cap on one request's
// work (plenoxd --max-render-pixels).
absl::Status CheckRenderPixels(const PinholeIntrinsics& intrinsics, int64_t max_pixels);

}  // namespace plx

// The viewer's render endpoint: a view of a map from a pose the page sends (a camera marker the
// user clicked, or the page's own 3D view), returned as a PNG a browser shows directly. The
// request's parameters are checked here, before any work: a malformed or oversized request is
// InvalidArgument (HTTP 400), never a render.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/render/render_view.h"
#include "web/http_server.h"

namespace plx::web {

// Each side of a viewer render is at most this, whatever --max-render-pixels allows: the page
// shows a preview, not a product (docs/LIMITS.md).
inline constexpr int kMaxViewerRenderSide = 1024;

enum class ViewerImage { kColor, kDepth };

struct ViewerRenderRequest {
  SE3 world_T_camera;  // OpenCV camera: x right, y down, z forward
  PinholeIntrinsics intrinsics;
  ViewerImage image = ViewerImage::kColor;
};

// From the query: pose=tx,ty,tz,qx,qy,qz,qw (world_T_camera, TUM order), width and height in
// pixels (1..kMaxViewerRenderSide, width * height at most `max_pixels`), fov = vertical field
// of view in degrees (1..170; square pixels, principal point at the centre) and
// image=color|depth. InvalidArgument naming the parameter otherwise (also for a pose outside the
// world extent the maps can hold).
absl::StatusOr<ViewerRenderRequest> ParseViewerRenderRequest(const HttpRequest& request,
                                                             int64_t max_pixels);

// The rendered view as a PNG: colour as rendered; depth as grey levels, near bright, far dark,
// black where the map renders nothing (scaled to the view's own depth range, which the
// X-Depth-Range header gives as "near,far" metres).
struct ViewerImagePng {
  std::string png;
  double near_m = 0.0, far_m = 0.0;  // depth only
};
absl::StatusOr<ViewerImagePng> EncodeViewerImage(const RenderedView& view, ViewerImage image);

}  // namespace plx::web

#include "web/viewer_render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/geometry/world_pose.h"
#include "core/io/image_io.h"

namespace plx::web {
namespace {

absl::StatusOr<std::string> Required(const HttpRequest& request, const char* name) {
  const std::string* value = request.Param(name);
  if (value == nullptr || value->empty()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": missing"));
  }
  return *value;
}

absl::StatusOr<int> IntParam(const HttpRequest& request, const char* name, int lo, int hi) {
  absl::StatusOr<std::string> text = Required(request, name);
  if (!text.ok()) return text.status();
  int value = 0;
  if (!absl::SimpleAtoi(*text, &value) || value < lo || value > hi) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": expected an integer in [", lo, ", ", hi, "], got \"",
                     text->substr(0, 32), "\""));
  }
  return value;
}

absl::StatusOr<SE3> PoseParam(const HttpRequest& request) {
  absl::StatusOr<std::string> text = Required(request, "pose");
  if (!text.ok()) return text.status();
  const std::vector<std::string> parts = absl::StrSplit(*text, ',');
  double v[7];
  bool ok = parts.size() == 7;
  for (size_t i = 0; ok && i < 7; ++i) {
    ok = absl::SimpleAtod(parts[i], &v[i]) && std::isfinite(v[i]);
  }
  if (!ok) {
    return absl::InvalidArgumentError(
        "pose: expected 7 finite numbers tx,ty,tz,qx,qy,qz,qw (world_T_camera)");
  }
  const std::optional<Eigen::Quaterniond> q =
      UnitQuaternion(Eigen::Quaterniond(v[6], v[3], v[4], v[5]), 1e-6);
  if (!q) return absl::InvalidArgumentError("pose: the quaternion is zero");
  const SE3 pose(*q, Eigen::Vector3d(v[0], v[1], v[2]));
  if (absl::Status s = CheckPoseInsideWorld(pose, "pose"); !s.ok()) {
    return absl::InvalidArgumentError(s.message());
  }
  return pose;
}

}  // namespace

absl::StatusOr<ViewerRenderRequest> ParseViewerRenderRequest(const HttpRequest& request,
                                                             int64_t max_pixels) {
  ViewerRenderRequest out;
  absl::StatusOr<SE3> pose = PoseParam(request);
  if (!pose.ok()) return pose.status();
  out.world_T_camera = *pose;
  absl::StatusOr<int> width = IntParam(request, "width", 1, kMaxViewerRenderSide);
  if (!width.ok()) return width.status();
  absl::StatusOr<int> height = IntParam(request, "height", 1, kMaxViewerRenderSide);
  if (!height.ok()) return height.status();
  if (int64_t{*width} * *height > max_pixels) {
    return absl::InvalidArgumentError(absl::StrCat(*width, " x ", *height,
                                                   " pixels: over the limit of ", max_pixels,
                                                   " pixels per render"));
  }
  absl::StatusOr<std::string> fov_text = Required(request, "fov");
  if (!fov_text.ok()) return fov_text.status();
  double fov = 0.0;
  if (!absl::SimpleAtod(*fov_text, &fov) || !(fov >= 1.0 && fov <= 170.0)) {
    return absl::InvalidArgumentError("fov: expected degrees in [1, 170]");
  }
  const double f = 0.5 * *height / std::tan(0.5 * fov * M_PI / 180.0);
  out.intrinsics = PinholeIntrinsics{f, f, 0.5 * *width, 0.5 * *height, *width, *height};
  const std::string* image = request.Param("image");
  if (image == nullptr || *image == "color") {
    out.image = ViewerImage::kColor;
  } else if (*image == "depth") {
    out.image = ViewerImage::kDepth;
  } else {
    return absl::InvalidArgumentError("image: expected color or depth");
  }
  return out;
}

absl::StatusOr<ViewerImagePng> EncodeViewerImage(const RenderedView& view, ViewerImage image) {
  ViewerImagePng out;
  if (image == ViewerImage::kColor) {
    absl::StatusOr<std::string> png = EncodeColorImage(view.color, ".png");
    if (!png.ok()) return png.status();
    out.png = std::move(*png);
    return out;
  }
  const DepthImage& z = view.z_depth;
  float near = std::numeric_limits<float>::infinity(), far = 0.0f;
  for (const float d : z.data) {
    if (d > 0.0f) {
      near = std::min(near, d);
      far = std::max(far, d);
    }
  }
  ColorImage grey(z.width, z.height, 3, 0.0f);
  if (far > 0.0f) {
    const float span = std::max(far - near, 1e-6f);
    for (int64_t i = 0; i < z.num_pixels(); ++i) {
      const float d = z.data[i];
      if (!(d > 0.0f)) continue;
      // Near 1.0, far 0.2: the farthest surface stays visibly apart from "nothing" (black).
      const float level = 1.0f - 0.8f * (d - near) / span;
      // A faint blue tint tells a depth image from a grey colour render at a glance.
      grey.data[3 * i + 0] = 0.9f * level;
      grey.data[3 * i + 1] = 0.95f * level;
      grey.data[3 * i + 2] = level;
    }
    out.near_m = near;
    out.far_m = far;
  }
  absl::StatusOr<std::string> png = EncodeColorImage(grey, ".png");
  if (!png.ok()) return png.status();
  out.png = std::move(*png);
  return out;
}

}  // namespace plx::web

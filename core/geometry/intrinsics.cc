#include "core/geometry/intrinsics.h"

#include <cmath>
#include <sstream>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/numbers.h"

namespace plx {

absl::Status ValidateCalibration(const CameraCalibration& c) {
  const PinholeIntrinsics& k = c.pinhole;
  if (!(std::isfinite(k.fx) && k.fx > 0 && std::isfinite(k.fy) && k.fy > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("focal lengths must be positive and finite, got fx=", k.fx, " fy=", k.fy));
  }
  if (!std::isfinite(k.cx) || !std::isfinite(k.cy)) {
    return absl::InvalidArgumentError("principal point must be finite");
  }
  if (k.width <= 0 || k.height <= 0 || k.width > kMaxImageSide || k.height > kMaxImageSide) {
    return absl::InvalidArgumentError(
        absl::StrCat("image size must be in 1..", kMaxImageSide, ", got ", k.width, "x", k.height));
  }
  if (!(std::isfinite(c.depth_scale) && c.depth_scale > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("depth scale must be positive, got ", c.depth_scale));
  }
  const Distortion& d = c.distortion;
  for (double v : {d.k1, d.k2, d.p1, d.p2, d.k3}) {
    if (!std::isfinite(v)) return absl::InvalidArgumentError("distortion must be finite");
  }
  return absl::OkStatus();
}

absl::StatusOr<PinholeIntrinsics> ParsePinholeIntrinsics(const std::string& text) {
  std::vector<std::string> parts =
      absl::StrSplit(text, absl::ByAnyChar(" ,\t"), absl::SkipEmpty());
  if (parts.size() != 6) {
    return absl::InvalidArgumentError(
        absl::StrCat("intrinsics need 6 numbers \"fx fy cx cy w h\", got \"", text, "\""));
  }
  double v[4];
  for (int i = 0; i < 4; ++i) {
    if (!absl::SimpleAtod(parts[i], &v[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("intrinsics: not a number: \"", parts[i], "\""));
    }
  }
  int w = 0, h = 0;
  if (!absl::SimpleAtoi(parts[4], &w) || !absl::SimpleAtoi(parts[5], &h)) {
    return absl::InvalidArgumentError("intrinsics: width and height must be integers");
  }
  PinholeIntrinsics k{v[0], v[1], v[2], v[3], w, h};
  CameraCalibration c;
  c.pinhole = k;
  if (absl::Status s = ValidateCalibration(c); !s.ok()) return s;
  return k;
}

}  // namespace plx

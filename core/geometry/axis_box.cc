#include "core/geometry/axis_box.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx {

absl::Status CheckAxisBox(const AxisBox& box, absl::string_view field) {
  constexpr const char* kAxes[] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(box.min[a]) || !std::isfinite(box.max[a])) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": coordinates must be finite, got ", AxisBoxText(box)));
    }
    if (!(box.min[a] < box.max[a])) {
      return absl::InvalidArgumentError(absl::StrCat(field, ": min must be below max on every ",
                                                     "axis, not on ", kAxes[a], " in ",
                                                     AxisBoxText(box)));
    }
  }
  return absl::OkStatus();
}

std::string AxisBoxText(const AxisBox& box) {
  return absl::StrFormat("[%g, %g, %g] .. [%g, %g, %g]", box.min[0], box.min[1], box.min[2],
                         box.max[0], box.max[1], box.max[2]);
}

}  // namespace plx

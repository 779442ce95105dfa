// An axis-aligned box in a map's (world) frame, metres: the region of a map a client asks for
// (a mesh of the room a headset is in, core/mesh/iso_surface.h's MeshOptions::region).
#pragma once

#include <array>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace plx {

struct AxisBox {
  std::array<double, 3> min = {0.0, 0.0, 0.0};
  std::array<double, 3> max = {0.0, 0.0, 0.0};

  bool operator==(const AxisBox&) const = default;
};

// InvalidArgument "<field>: ..." unless every coordinate is finite and min < max on every axis
// (an empty or inverted box is a client's mistake, not a request for nothing). Any finite
// extent is allowed: a box reaching past the map (a floor-to-ceiling slab of 1e9 m) simply
// covers all of it on that axis.
absl::Status CheckAxisBox(const AxisBox& box, absl::string_view field);

// "[xmin, ymin, zmin] .. [xmax, ymax, zmax]" for messages and summaries.
std::string AxisBoxText(const AxisBox& box);

}  // namespace plx

// What `plenox render` takes and prints, in-process (cmd_render.cc) and on a daemon
// (remote_render.cc): the flags and their checks, the all-or-nothing write of the images and
// the summary line, written once so that the two forms cannot drift apart.
#pragma once

#include <optional>
#include <string>

#include "absl/status/status.h"
#include "clients/plenox/cli_common.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"

namespace plx::cli {

// --map (`map_value` and `map_help` say whether it is a file or a map on the daemon), --pose,
// --intrinsics, --color and --depth, in that order.
void AddRenderFlags(FlagSet& flags, const std::string& map_value, const std::string& map_help);

// The camera and the images asked for.
struct RenderTarget {
  SE3 pose;  // world_T_camera
  PinholeIntrinsics intrinsics;
  std::string color_path;  // empty: no colour image
  std::string depth_path;  // empty: no depth image
};

// The render flags' values, checked before any work. On an error it prints it and returns
// nullopt with *exit_code set: usage (2) for a bad value or neither image asked for, failure
// (1) when an image's folder does not exist.
std::optional<RenderTarget> RenderTargetFromFlagsOrReport(const std::string& command,
                                                          const FlagSet& flags, int* exit_code);

// Writes the images asked for (their PNG bytes) under temporary names and renames them only
// when both were written, so a failed render leaves no output behind.
absl::Status WriteRenderImages(const RenderTarget& target, const std::string& color_png,
                               const std::string& depth_png);

// "rendered 640x480<where>, 97.5% of pixels hit the map, colour -> c.png, depth -> d.png".
std::string RenderSummaryText(const RenderTarget& target, const std::string& where,
                              double coverage);

}  // namespace plx::cli

#include "clients/plenox/render_flags.h"

#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/io/atomic_write.h"
#include "core/formats/pose_text.h"

namespace plx::cli {

void AddRenderFlags(FlagSet& flags, const std::string& map_value, const std::string& map_help) {
  flags.Add("map", map_value, map_help, std::nullopt, true)
      .Add("pose", "\"tx ty tz qx qy qz qw\"", "world_T_camera (camera-to-world), OpenCV axes",
           std::nullopt, true)
      .Add("intrinsics", "\"fx fy cx cy w h\"", "pinhole intrinsics and image size", std::nullopt,
           true)
      .Add("color", "C.png", "colour image to write")
      .Add("depth", "D.png", "depth image to write");
}

std::optional<RenderTarget> RenderTargetFromFlagsOrReport(const std::string& command,
                                                          const FlagSet& flags, int* exit_code) {
  RenderTarget target;
  target.color_path = flags.GetString("color");
  target.depth_path = flags.GetString("depth");
  if (target.color_path.empty() && target.depth_path.empty()) {
    *exit_code = ReportError(command, absl::InvalidArgumentError("give --color, --depth or both"),
                             /*usage_error=*/true);
    return std::nullopt;
  }
  absl::StatusOr<SE3> pose = ParsePoseText(flags.GetString("pose"));
  if (!pose.ok()) {
    *exit_code = ReportError(command, pose.status(), /*usage_error=*/true);
    return std::nullopt;
  }
  target.pose = *pose;
  absl::StatusOr<PinholeIntrinsics> k = ParsePinholeIntrinsics(flags.GetString("intrinsics"));
  if (!k.ok()) {
    *exit_code = ReportError(command, k.status(), /*usage_error=*/true);
    return std::nullopt;
  }
  target.intrinsics = *k;
  for (const std::string& path : {target.color_path, target.depth_path}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) {
      *exit_code = ReportError(command, s);
      return std::nullopt;
    }
  }
  return target;
}

absl::Status WriteRenderImages(const RenderTarget& target, const std::string& color_png,
                               const std::string& depth_png) {
  std::vector<std::pair<std::string, std::string>> files;
  if (!target.color_path.empty()) files.emplace_back(target.color_path, color_png);
  if (!target.depth_path.empty()) files.emplace_back(target.depth_path, depth_png);
  return WriteFilesAtomically(files, "cannot write the render");
}

std::string RenderSummaryText(const RenderTarget& target, const std::string& where,
                              double coverage) {
  return absl::StrFormat("rendered %dx%d%s, %.1f%% of pixels hit the map%s%s",
                         target.intrinsics.width, target.intrinsics.height, where,
                         100.0 * coverage,
                         target.color_path.empty() ? "" : ", colour -> " + target.color_path,
                         target.depth_path.empty() ? "" : ", depth -> " + target.depth_path);
}

}  // namespace plx::cli

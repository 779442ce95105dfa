// plenox render: colour and depth images of a map from a given camera.
#include <iostream>
#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "core/formats/map_file.h"
#include "core/formats/pose_text.h"
#include "core/io/atomic_write.h"
#include "core/io/image_io.h"
#include "core/render/render_view.h"

namespace plx::cli {

int RunRender(const std::vector<std::string>& args) {
  FlagSet flags("plenox render",
                "Renders a map from a camera pose. The colour image is 8-bit RGB; the depth\n"
                "image is a 16-bit PNG of z-depth in millimetres, 0 where the map renders\n"
                "nothing (opacity below 0.5).");
  flags.Add("map", "MAP", "map file", std::nullopt, true)
      .Add("pose", "\"tx ty tz qx qy qz qw\"", "world_T_camera (camera-to-world), OpenCV axes",
           std::nullopt, true)
      .Add("intrinsics", "\"fx fy cx cy w h\"", "pinhole intrinsics and image size", std::nullopt,
           true)
      .Add("color", "C.png", "colour image to write")
      .Add("depth", "D.png", "depth image to write")
      .AddSwitch("json", "print a JSON summary on the last line of stdout");
  AddBackendFlags(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  const std::string color_path = flags.GetString("color"), depth_path = flags.GetString("depth");
  if (color_path.empty() && depth_path.empty()) {
    return ReportError("render", absl::InvalidArgumentError("give --color, --depth or both"), true);
  }
  absl::StatusOr<SE3> pose = ParsePoseText(flags.GetString("pose"));
  if (!pose.ok()) return ReportError("render", pose.status(), true);
  absl::StatusOr<PinholeIntrinsics> k = ParsePinholeIntrinsics(flags.GetString("intrinsics"));
  if (!k.ok()) return ReportError("render", k.status(), true);

  for (const std::string& path : {color_path, depth_path}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError("render", s);
  }

  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("render", flags, &exit_code);
  if (!backend) return exit_code;

  absl::StatusOr<std::unique_ptr<PlenoxelMap>> map = LoadMap(flags.GetString("map"));
  if (!map.ok()) return ReportError("render", map.status());
  absl::StatusOr<RenderedView> rendered_view = RenderView(*backend, **map, *pose, *k);
  if (!rendered_view.ok()) return ReportError("render", rendered_view.status());
  const RenderedView& view = *rendered_view;
  // Both images are written under temporary names and renamed only when both were written, so
  // a failed render leaves no output behind.
  std::vector<std::pair<std::string, std::string>> files;
  if (!color_path.empty()) {
    absl::StatusOr<std::string> png = EncodeColorImage(view.color, ".png");
    if (!png.ok()) return ReportError("render", png.status());
    files.emplace_back(color_path, std::move(*png));
  }
  if (!depth_path.empty()) {
    absl::StatusOr<std::string> png = EncodeDepthImage(view.z_depth, 1000.0);
    if (!png.ok()) return ReportError("render", png.status());
    files.emplace_back(depth_path, std::move(*png));
  }
  if (absl::Status s = WriteFilesAtomically(files, "cannot write the render"); !s.ok()) {
    return ReportError("render", s);
  }
  int64_t rendered = 0;
  for (float o : view.opacity.data) rendered += o >= kRenderedOpacity;
  const double coverage = static_cast<double>(rendered) / view.opacity.num_pixels();
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("width", k->width)
        .Add("height", k->height)
        .Add("coverage", coverage)
        .Add("color", color_path)
        .Add("depth", depth_path)
        .Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("rendered %dx%d on %s, %.1f%% of pixels hit the map%s%s\n",
                                 k->width, k->height, BackendText(*backend), 100.0 * coverage,
                                 color_path.empty() ? "" : ", colour -> " + color_path,
                                 depth_path.empty() ? "" : ", depth -> " + depth_path);
  }
  return kExitOk;
}

}  // namespace plx::cli

// plenox render: colour and depth images of a map from a given camera.
#include <iostream>
#include <string>
#include <utility>

#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/render_flags.h"
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
  AddRenderFlags(flags, "MAP", "map file");
  flags.AddSwitch("json", "print a JSON summary on the last line of stdout");
  AddBackendFlags(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  const std::optional<RenderTarget> target =
      RenderTargetFromFlagsOrReport("render", flags, &exit_code);
  if (!target) return exit_code;
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("render", flags, &exit_code);
  if (!backend) return exit_code;

  std::unique_ptr<PlenoxelMap> map = LoadMapOrReport("render", flags, *backend, &exit_code);
  if (!map) return exit_code;
  absl::StatusOr<RenderedView> rendered_view =
      RenderView(*backend, *map, target->pose, target->intrinsics);
  if (!rendered_view.ok()) return ReportError("render", rendered_view.status());
  const RenderedView& view = *rendered_view;
  std::string color_png, depth_png;  // only the images asked for are encoded
  if (!target->color_path.empty()) {
    absl::StatusOr<std::string> png = EncodeColorImage(view.color, ".png");
    if (!png.ok()) return ReportError("render", png.status());
    color_png = std::move(*png);
  }
  if (!target->depth_path.empty()) {
    absl::StatusOr<std::string> png = EncodeDepthImage(view.z_depth, 1000.0);
    if (!png.ok()) return ReportError("render", png.status());
    depth_png = std::move(*png);
  }
  if (absl::Status s = WriteRenderImages(*target, color_png, depth_png); !s.ok()) {
    return ReportError("render", s);
  }
  int64_t rendered = 0;
  for (float o : view.opacity.data) rendered += o >= kRenderedOpacity;
  const double coverage = static_cast<double>(rendered) / view.opacity.num_pixels();
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("width", target->intrinsics.width)
        .Add("height", target->intrinsics.height)
        .Add("coverage", coverage)
        .Add("color", target->color_path)
        .Add("depth", target->depth_path)
        .Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else {
    std::cout << RenderSummaryText(*target, " on " + BackendText(*backend), coverage) << "\n";
  }
  return kExitOk;
}

}  // namespace plx::cli

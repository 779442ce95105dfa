// plenox --server HOST:PORT render: colour and depth images of a map on the daemon (Render).
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "core/formats/pose_text.h"
#include "core/io/atomic_write.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "render";

}  // namespace

int RunRemoteRender(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox render",
                "With --server: renders map N on the daemon from a camera pose. The colour\n"
                "image is 8-bit RGB; the depth image is a 16-bit PNG of z-depth in millimetres,\n"
                "0 where the map renders nothing. Both are the daemon's PNG bytes as sent.");
  flags.Add("map", "N", "the map on the daemon", std::nullopt, true)
      .Add("pose", "\"tx ty tz qx qy qz qw\"", "world_T_camera (camera-to-world), OpenCV axes",
           std::nullopt, true)
      .Add("intrinsics", "\"fx fy cx cy w h\"", "pinhole intrinsics and image size", std::nullopt,
           true)
      .Add("color", "C.png", "colour image to write")
      .Add("depth", "D.png", "depth image to write");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  const std::string color_path = flags.GetString("color"), depth_path = flags.GetString("depth");
  if (color_path.empty() && depth_path.empty()) {
    return ReportError(kCommand, absl::InvalidArgumentError("give --color, --depth or both"), true);
  }
  absl::StatusOr<SE3> pose = ParsePoseText(flags.GetString("pose"));
  if (!pose.ok()) return ReportError(kCommand, pose.status(), true);
  absl::StatusOr<PinholeIntrinsics> k = ParsePinholeIntrinsics(flags.GetString("intrinsics"));
  if (!k.ok()) return ReportError(kCommand, k.status(), true);
  for (const std::string& path : {color_path, depth_path}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError(kCommand, s);
  }

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  pb::RenderRequest request;
  request.set_map(flags.GetString("map"));
  PoseToProto(*pose, request.mutable_pose());
  IntrinsicsToProto(*k, /*depth_scale=*/0.0, request.mutable_intrinsics());
  request.set_color_encoding(pb::COLOR_ENCODING_PNG);
  request.set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
  absl::StatusOr<pb::RenderResponse> response = client->Render(request);
  if (!response.ok()) return ReportError(kCommand, response.status());
  if (response->width() != static_cast<uint32_t>(k->width) ||
      response->height() != static_cast<uint32_t>(k->height) ||
      response->color_encoding() != pb::COLOR_ENCODING_PNG ||
      response->depth_encoding() != pb::DEPTH_ENCODING_PNG16) {
    return ReportError(kCommand, absl::InternalError(absl::StrFormat(
                                     "the daemon answered with %dx%d images (encodings %d, %d) "
                                     "instead of %dx%d PNGs",
                                     response->width(), response->height(),
                                     static_cast<int>(response->color_encoding()),
                                     static_cast<int>(response->depth_encoding()),
                                     k->width, k->height)));
  }
  // Both images go to temporary names first and are renamed only when both were written, so a
  // failure leaves no output behind (as in-process render).
  std::vector<std::pair<std::string, std::string>> files;
  if (!color_path.empty()) files.emplace_back(color_path, response->color());
  if (!depth_path.empty()) files.emplace_back(depth_path, response->depth());
  if (absl::Status s = WriteFilesAtomically(files, "cannot write the render"); !s.ok()) return ReportError(kCommand, s);
  std::cout << absl::StrFormat(
      "rendered %dx%d (map version %d on %s), %.1f%% of pixels hit the map%s%s\n", k->width,
      k->height, response->map_version(), client->server(), 100.0 * response->coverage(),
      color_path.empty() ? "" : ", colour -> " + color_path,
      depth_path.empty() ? "" : ", depth -> " + depth_path);
  return kExitOk;
}

}  // namespace plx::cli

// plenox --server HOST:PORT render: colour and depth images of a map on the daemon (Render).
#include <iostream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/render_flags.h"
#include "core/formats/pose_text.h"
#include "core/io/atomic_write.h"
#include "proto/render_size.h"

namespace plx::cli {

int RunRemoteRender(const RemoteOptions& remote, const std::vector<std::string>& args) {
  constexpr char kCommand[] = "render";
  FlagSet flags("plenox render",
                "With --server: renders map N on the daemon from a camera pose. The colour\n"
                "image is 8-bit RGB; the depth image is a 16-bit PNG of z-depth in millimetres,\n"
                "0 where the map renders nothing. Both are the daemon's PNG bytes as sent.");
  AddRenderFlags(flags, "N", "the map on the daemon");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  const std::optional<RenderTarget> target =
      RenderTargetFromFlagsOrReport(kCommand, flags, &exit_code);
  if (!target) return exit_code;
  const PinholeIntrinsics& k = target->intrinsics;

  pb::RenderRequest request;
  request.set_map(flags.GetString("map"));
  PoseToProto(target->pose, request.mutable_pose());
  IntrinsicsToProto(k, /*depth_scale=*/0.0, request.mutable_intrinsics());
  request.set_color_encoding(pb::COLOR_ENCODING_PNG);
  request.set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
  // Whatever the daemon's --max-message-mb, this client receives at most
  // kRemoteMaxMessageBytes: an answer that may be larger is not asked for (the daemon's rule).
  if (absl::Status s = CheckRenderResponseSize(request, kRemoteMaxMessageBytes); !s.ok()) {
    return ReportError(kCommand, absl::Status(s.code(), absl::StrCat("--intrinsics: ", s.message(),
                                                                     " plenox receives")));
  }
  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  absl::StatusOr<pb::RenderResponse> response = client->Render(request);
  if (!response.ok()) return ReportError(kCommand, response.status());
  if (response->width() != static_cast<uint32_t>(k.width) ||
      response->height() != static_cast<uint32_t>(k.height) ||
      response->color_encoding() != pb::COLOR_ENCODING_PNG ||
      response->depth_encoding() != pb::DEPTH_ENCODING_PNG16) {
    return ReportError(kCommand, absl::InternalError(absl::StrFormat(
                                     "the daemon answered with %dx%d images (encodings %d, %d) "
                                     "instead of %dx%d PNGs",
                                     response->width(), response->height(),
                                     static_cast<int>(response->color_encoding()),
                                     static_cast<int>(response->depth_encoding()),
                                     k.width, k.height)));
  }
  // The daemon's PNG bytes as sent, all or nothing as in-process render.
  if (absl::Status s = WriteRenderImages(*target, response->color(), response->depth());
      !s.ok()) {
    return ReportError(kCommand, s);
  }
  std::cout << RenderSummaryText(*target,
                                 absl::StrFormat(" (map version %d on %s)",
                                                 response->map_version(), client->server()),
                                 response->coverage())
            << "\n";
  return kExitOk;
}

}  // namespace plx::cli

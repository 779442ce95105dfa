// plenox --server HOST:PORT export: a map on the daemon as a PLY point cloud or triangle mesh
// (Export stream).
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/export_flags.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "export";

// An element's count from a PLY header ("element vertex N"), -1 when the header lacks it.
int64_t ElementCount(const std::string& head, const std::string& element) {
  const std::string key = "\nelement " + element + " ";
  const size_t at = head.find(key);
  const size_t header_end = head.find("end_header");
  if (at == std::string::npos || (header_end != std::string::npos && at > header_end)) return -1;
  const size_t begin = at + key.size();
  const size_t end = head.find('\n', begin);
  if (end == std::string::npos) return -1;
  int64_t count = 0;
  return absl::SimpleAtoi(head.substr(begin, end - begin), &count) ? count : -1;
}

}  // namespace

int RunRemoteExport(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox export",
                "With --server: writes map N on the daemon as binary little-endian PLY, a\n"
                "coloured point cloud (one point per voxel vertex on the surface of the density\n"
                "field) or, with --mesh, a triangle mesh built on the daemon's device. The file\n"
                "appears only once it is complete.");
  flags.Add("map", "N", "the map on the daemon", std::nullopt, true);
  AddExportFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<ExportChoice> choice = ExportChoiceFromFlags(flags);
  if (!choice.ok()) return ReportError(kCommand, choice.status(), true);
  const std::string map_name = flags.GetString("map");
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError(kCommand, s);

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  pb::ExportRequest request;
  request.set_map(map_name);
  if (choice->mesh) {
    // Defaults resolved by the flags are sent as they are: the daemon applies the same ones.
    const MeshOptions& o = choice->mesh_options;
    request.set_format(pb::EXPORT_FORMAT_MESH);
    request.set_iso_level(o.iso_level);
    request.set_min_component_triangles(static_cast<uint64_t>(o.min_component_triangles));
    request.set_max_triangles(static_cast<uint64_t>(o.max_triangles));
    request.set_keep_unobserved(o.keep_unobserved);
    request.set_mesh_color(o.color_mode == MeshColorMode::kViewAlongNormal
                               ? pb::MESH_COLOR_ALONG_NORMAL
                               : pb::MESH_COLOR_DC);
  } else {
    request.set_min_density(static_cast<float>(choice->min_density));
  }
  std::unique_ptr<grpc::ClientContext> context =
      client->NewContext(absl::InfiniteDuration(), map_name);
  std::unique_ptr<grpc::ClientReader<pb::ExportChunk>> stream =
      client->stub().Export(context.get(), request);

  // Chunks go straight to a temporary file next to `out` (large maps give hundreds of MB),
  // which is renamed over `out` only when the last chunk arrived and the call succeeded.
  const std::string temp = absl::StrFormat("%s.tmp.%d.ply", out, static_cast<int>(getpid()));
  std::FILE* file = nullptr;
  absl::Status problem = absl::OkStatus();
  ProgressLine line(!flags.GetSwitch("quiet"));
  std::string head;  // the first bytes, for the header
  uint64_t received = 0;
  bool last = false;
  pb::ExportChunk chunk;
  while (stream->Read(&chunk)) {
    if (!problem.ok()) continue;  // drain after a local problem; the call is being cancelled
    if (last || chunk.offset() != received) {
      problem = absl::InternalError(absl::StrFormat(
          "the daemon sent a chunk at offset %d after %d bytes%s", chunk.offset(), received,
          last ? " and the last chunk" : ""));
    } else if (file == nullptr && (file = std::fopen(temp.c_str(), "wb")) == nullptr) {
      problem = absl::InternalError(
          absl::StrFormat("cannot write %s: %s", out, std::strerror(errno)));
    } else if (std::fwrite(chunk.data().data(), 1, chunk.data().size(), file) !=
               chunk.data().size()) {
      problem = absl::InternalError(
          absl::StrFormat("cannot write %s: %s", out, std::strerror(errno)));
    }
    if (!problem.ok()) {
      context->TryCancel();
      continue;
    }
    if (head.size() < 4096) head.append(chunk.data().substr(0, 4096 - head.size()));
    received += chunk.data().size();
    last = chunk.last();
    line.Update(absl::StrFormat("export \"%s\": %.1f MB received", map_name, received / 1e6));
  }
  const grpc::Status finished = stream->Finish();
  if (problem.ok() && !finished.ok()) problem = client->ToStatus(finished);
  if (problem.ok() && !last) {
    problem = absl::InternalError("the daemon ended the Export stream before the last chunk");
  }
  if (file != nullptr) {
    const bool flushed = std::fflush(file) == 0 && fsync(fileno(file)) == 0;
    const std::string reason = std::strerror(errno);
    if ((std::fclose(file) != 0 || !flushed) && problem.ok()) {
      problem = absl::InternalError(absl::StrFormat("cannot write %s: %s", out, reason));
    }
  }
  if (problem.ok() && std::rename(temp.c_str(), out.c_str()) != 0) {
    problem = absl::InternalError(absl::StrFormat("cannot write %s: %s", out, std::strerror(errno)));
  }
  if (!problem.ok()) {
    if (file != nullptr) std::remove(temp.c_str());
    if (received > 0) line.Finish("export failed");
    return ReportError(kCommand, problem);
  }
  const int64_t points = ElementCount(head, "vertex");
  const int64_t faces = ElementCount(head, "face");
  const std::string what = choice->mesh
                               ? absl::StrFormat("%d vertices, %d triangles", points, faces)
                               : absl::StrFormat("%d points", points);
  line.Finish(absl::StrFormat("exported \"%s\" from %s: %s, %.1f MB", map_name,
                              client->server(), what, received / 1e6));
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("map", map_name).Add("server", client->server()).Add("out", out);
    if (choice->mesh) {
      json.Add("vertices", points).Add("faces", faces);
    } else {
      json.Add("points", points);
    }
    json.Add("bytes", static_cast<int64_t>(received));
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("wrote %s (%s, %.1f MB)\n", out, what, received / 1e6);
  }
  return kExitOk;
}

}  // namespace plx::cli

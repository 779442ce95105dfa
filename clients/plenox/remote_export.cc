// plenox --server HOST:PORT export: a map on the daemon as a PLY point cloud, or a triangle mesh
// as PLY or binary glTF, optionally simplified to a triangle budget (Export stream).
#include <functional>
#include <iostream>
#include <optional>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/export_flags.h"
#include "clients/plenox/export_output.h"
#include "clients/plenox/remote_client.h"
#include "core/formats/glb_mesh.h"
#include "core/formats/ply_mesh.h"
#include "core/io/atomic_write.h"
#include "proto/export_codec.h"

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

// Whether a PLY header (up to end_header) has the region comment (core/formats/ply_mesh.h).
bool RegionCommentIn(const std::string& head) {
  const size_t at = head.find(absl::StrCat("\n", kPlyRegionComment));
  const size_t header_end = head.find("end_header");
  return at != std::string::npos && (header_end == std::string::npos || at < header_end);
}

FlagSet RemoteExportFlags() {
  FlagSet flags("plenox export",
                "With --server: writes map N on the daemon as a coloured point cloud (binary\n"
                "little-endian PLY, one point per voxel vertex on the surface of the density\n"
                "field) or, with --mesh, a triangle mesh built on the daemon's device, as PLY\n"
                "or (--format glb, or an --out ending in .glb) binary glTF 2.0; --lod-triangles\n"
                "N simplifies it to at most N triangles; --bbox meshes only a box of the\n"
                "map. The file appears only once it is complete.");
  flags.Add("map", "N", "the map on the daemon", std::nullopt, true);
  AddExportFlags(flags);
  AddJsonAndQuietSwitches(flags);
  return flags;
}

// The most of a file's beginning kept for reading its counts: a PLY header or a GLB's header
// and JSON chunk (about 2 kB plus the map's source text).
constexpr size_t kHeadBytes = 64 * 1024;

// What an Export stream delivered into `out`.
struct ExportedFile {
  std::string head;  // the first bytes, for the PLY header or the GLB's JSON chunk
  uint64_t bytes = 0;
};

// Checks a received file before it replaces `out` (counts what it holds into `summary`).
using ExportCheck = std::function<absl::Status(const ExportedFile&)>;

// Receives the chunks straight into a temporary next to `out` (large maps give hundreds of MB),
// renamed over `out` only when the last chunk arrived and the call succeeded.
absl::StatusOr<ExportedFile> ReceiveExport(RemoteClient& client, const pb::ExportRequest& request,
                                           const std::string& out, const ExportCheck& check,
                                           ProgressLine& line) {
  std::unique_ptr<grpc::ClientContext> context =
      client.NewContext(absl::InfiniteDuration(), request.map());
  std::unique_ptr<grpc::ClientReader<pb::ExportChunk>> stream =
      client.stub().Export(context.get(), request);
  const std::string what = absl::StrCat("cannot write ", out);
  std::optional<AtomicFileWriter> file;  // opened with the first chunk
  absl::Status problem = absl::OkStatus();
  ExportedFile exported;
  bool last = false;
  pb::ExportChunk chunk;
  while (stream->Read(&chunk)) {
    if (!problem.ok()) continue;  // drain after a local problem; the call is being cancelled
    if (last || chunk.offset() != exported.bytes) {
      problem = absl::InternalError(absl::StrFormat(
          "the daemon sent a chunk at offset %d after %d bytes%s", chunk.offset(), exported.bytes,
          last ? " and the last chunk" : ""));
    } else if (!file) {
      absl::StatusOr<AtomicFileWriter> opened = AtomicFileWriter::Open(out, what);
      if (opened.ok()) file.emplace(std::move(*opened));
      problem = opened.status();
    }
    if (problem.ok()) problem = file->Write(chunk.data());
    if (!problem.ok()) {
      context->TryCancel();
      continue;
    }
    if (exported.head.size() < kHeadBytes) {
      exported.head.append(chunk.data().substr(0, kHeadBytes - exported.head.size()));
    }
    exported.bytes += chunk.data().size();
    last = chunk.last();
    line.Update(
        absl::StrFormat("export \"%s\": %.1f MB received", request.map(), exported.bytes / 1e6));
  }
  const grpc::Status finished = stream->Finish();
  if (problem.ok() && !finished.ok()) problem = client.ToStatus(finished);
  if (problem.ok() && !last) {
    problem = absl::InternalError("the daemon ended the Export stream before the last chunk");
  }
  if (problem.ok()) problem = check(exported);
  if (problem.ok()) problem = file->Finish();
  if (problem.ok()) problem = file->Commit();
  if (!problem.ok()) {
    if (exported.bytes > 0) line.Finish("export failed");
    return problem;  // `file` removes its temporary
  }
  return exported;
}

// What the file holds, read from its beginning: the PLY header's counts, or the GLB's JSON
// chunk (vertices, triangles, and what simplification did). A file of the wrong kind, a level
// of detail over its budget (a daemon older than lod_triangles sends the full mesh) or a file
// that does not record the region asked for (a daemon older than region sends the whole map)
// is refused before it replaces `out`.
absl::Status CheckAndCount(const ExportSpec& spec, const ExportedFile& file,
                           ExportSummary* summary) {
  summary->bytes = file.bytes;
  const std::optional<AxisBox>& region = spec.mesh_options.region;
  std::optional<AxisBox> recorded;  // the region the file says it holds
  if (spec.mesh && spec.mesh_format == MeshFileFormat::kGlb) {
    absl::StatusOr<GlbMeshInfo> info = ReadGlbMeshInfo(file.head);
    if (!info.ok()) {
      return absl::InternalError(absl::StrCat(
          "the daemon's answer is not the glTF file asked for: ", info.status().message()));
    }
    summary->vertices = info->vertices;
    summary->faces = info->triangles;
    summary->full_faces = info->full_triangles > 0 ? info->full_triangles : info->triangles;
    summary->lod_error_m = info->lod_error_m;
    recorded = info->region;
  } else {
    if (file.head.rfind("ply\n", 0) != 0) {
      return absl::InternalError("the daemon's answer is not the PLY file asked for");
    }
    summary->vertices = ElementCount(file.head, "vertex");
    summary->faces = spec.mesh ? ElementCount(file.head, "face") : 0;
    summary->full_faces = summary->faces;  // a PLY does not say; the LOD check follows
    if (region && RegionCommentIn(file.head)) recorded = region;
  }
  if (spec.mesh && spec.lod_triangles > 0 && summary->faces > spec.lod_triangles) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "the daemon sent %d triangles for a level of detail of at most %d: it does not know "
        "lod_triangles (older than this client); nothing was written",
        summary->faces, spec.lod_triangles));
  }
  if (spec.mesh && region && !recorded) {
    return absl::FailedPreconditionError(
        "the daemon's file does not record the --bbox region: it does not know the region "
        "field (older than this client) and sent the whole map; nothing was written");
  }
  summary->region = region;
  return absl::OkStatus();
}

}  // namespace

int RunRemoteExport(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags = RemoteExportFlags();
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<ExportSpec> spec = ExportSpecFromFlags(flags);
  if (!spec.ok()) return ReportError(kCommand, spec.status(), true);
  const std::string map_name = flags.GetString("map");
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError(kCommand, s);

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  ProgressLine line(!flags.GetSwitch("quiet"));
  pb::ExportRequest request = ExportSpecToProto(*spec);
  request.set_map(map_name);
  ExportSummary summary;
  summary.mesh = spec->mesh;
  summary.format = spec->mesh_format;
  const ExportCheck check = [&](const ExportedFile& file) {
    return CheckAndCount(*spec, file, &summary);
  };
  absl::StatusOr<ExportedFile> exported = ReceiveExport(*client, request, out, check, line);
  if (!exported.ok()) return ReportError(kCommand, exported.status());
  const double mb = exported->bytes / 1e6;
  const std::string what = ExportSummaryText(summary);
  line.Finish(absl::StrFormat("exported \"%s\" from %s: %s, %.1f MB", map_name,
                              client->server(), what, mb));
  if (!flags.GetSwitch("json")) {
    std::cout << absl::StrFormat("wrote %s (%s, %.1f MB)\n", out, what, mb);
    return kExitOk;
  }
  JsonObject json;
  json.Add("map", map_name).Add("server", client->server()).Add("out", out);
  AddExportSummaryJson(json, summary);
  std::cout << json.str() << "\n";
  return kExitOk;
}

}  // namespace plx::cli

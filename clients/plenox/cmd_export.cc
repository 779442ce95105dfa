// plenox export (in-process): a map file as a PLY point cloud or, with --mesh, a triangle mesh.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/export_flags.h"
#include "core/export/map_export.h"
#include "core/io/atomic_write.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "export";

}  // namespace

int RunExport(const std::vector<std::string>& args) {
  FlagSet flags("plenox export",
                "Writes a map as binary little-endian PLY: a coloured point cloud (one point per\n"
                "voxel vertex on the surface of the density field) or, with --mesh, a triangle\n"
                "mesh (marching cubes on the density field; vertex x y z nx ny nz red green\n"
                "blue, face vertex_indices) that MeshLab, Open3D and Blender open. With --server,\n"
                "--map names a map on the daemon instead of a file.");
  flags.Add("map", "MAP", "map file", std::nullopt, true);
  AddExportFlags(flags);
  AddBackendFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<ExportSpec> spec = ExportSpecFromFlags(flags);
  if (!spec.ok()) return ReportError(kCommand, spec.status(), true);
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError(kCommand, s);
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport(kCommand, flags, &exit_code);
  if (!backend) return exit_code;
  std::unique_ptr<PlenoxelMap> map = LoadMapOrReport(kCommand, flags, *backend, &exit_code);
  if (!map) return exit_code;

  absl::StatusOr<MapPly> ply = ExportMapPly(*spec, *map, *backend);
  if (!ply.ok()) return ReportError(kCommand, ply.status());
  const std::string& bytes = ply->bytes;
  if (absl::Status s = WriteFileAtomically(out, bytes, "export"); !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("map", flags.GetString("map")).Add("out", out);
    if (spec->mesh) {
      json.Add("vertices", ply->vertices).Add("faces", ply->faces);
    } else {
      json.Add("points", ply->vertices);
    }
    json.Add("bytes", static_cast<int64_t>(bytes.size())).Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else if (spec->mesh) {
    std::cout << absl::StrFormat("wrote %s (%d vertices, %d triangles, %.1f MB)\n", out,
                                 ply->vertices, ply->faces, bytes.size() / 1e6);
  } else {
    std::cout << absl::StrFormat("wrote %s (%d points, %.1f MB)\n", out, ply->vertices,
                                 bytes.size() / 1e6);
  }
  return kExitOk;
}

}  // namespace plx::cli

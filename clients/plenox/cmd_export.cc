// plenox export (in-process): a map file as a PLY point cloud or, with --mesh, a triangle mesh
// as PLY or binary glTF, optionally simplified to a triangle budget.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/export_flags.h"
#include "clients/plenox/export_output.h"
#include "core/export/map_export.h"
#include "core/io/atomic_write.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "export";

}  // namespace

int RunExport(const std::vector<std::string>& args) {
  FlagSet flags("plenox export",
                "Writes a map as a coloured point cloud (binary little-endian PLY, one point per\n"
                "voxel vertex on the surface of the density field) or, with --mesh, a triangle\n"
                "mesh with normals and vertex colours (marching cubes on the surface the map's\n"
                "keyframes saw, or on the density field: --mesh-surface): as\n"
                "PLY (MeshLab, Open3D, Blender) or, with --format glb or an --out ending in\n"
                ".glb, as binary glTF 2.0 (headsets, three.js, Blender, game engines).\n"
                "--lod-triangles N simplifies the mesh to at most N triangles (a level of\n"
                "detail); --bbox meshes only a box of the map. With --server, --map names a\n"
                "map on the daemon instead of a file.");
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
  MapFileState state;
  std::unique_ptr<PlenoxelMap> map =
      LoadMapOrReport(kCommand, flags, *backend, &exit_code, &state);
  if (!map) return exit_code;

  absl::StatusOr<MapExport> file = ExportMap(*spec, *map, state.keyframes, *backend);
  if (!file.ok()) return ReportError(kCommand, file.status());
  if (absl::Status s = WriteFileAtomically(out, file->bytes, "export"); !s.ok()) {
    return ReportError(kCommand, s);
  }
  ExportSummary summary;
  summary.mesh = spec->mesh;
  summary.format = spec->mesh_format;
  summary.vertices = file->vertices;
  summary.faces = file->faces;
  summary.full_faces = file->full_faces;
  summary.lod_error_m = file->lod_error_m;
  summary.region = spec->mesh_options.region;
  summary.bytes = file->bytes.size();
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("map", flags.GetString("map")).Add("out", out);
    AddExportSummaryJson(json, summary);
    json.Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("wrote %s (%s, %.1f MB)\n", out, ExportSummaryText(summary),
                                 summary.bytes / 1e6);
  }
  return kExitOk;
}

}  // namespace plx::cli

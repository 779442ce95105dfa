// plenox export (in-process): a map file as a PLY point cloud or, with --mesh, a triangle mesh.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/export_flags.h"
#include "core/formats/ply_export.h"
#include "core/formats/ply_mesh.h"
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
  absl::StatusOr<ExportChoice> choice = ExportChoiceFromFlags(flags);
  if (!choice.ok()) return ReportError(kCommand, choice.status(), true);
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError(kCommand, s);
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport(kCommand, flags, &exit_code);
  if (!backend) return exit_code;
  std::unique_ptr<PlenoxelMap> map = LoadMapOrReport(kCommand, flags, *backend, &exit_code);
  if (!map) return exit_code;

  std::string bytes;
  int64_t vertices = 0, faces = 0;
  if (choice->mesh) {
    absl::StatusOr<TriangleMesh> mesh = ExtractMesh(map->grid, *backend, choice->mesh_options);
    if (!mesh.ok()) return ReportError(kCommand, mesh.status());
    absl::StatusOr<PlyMesh> ply = EncodePlyMesh(*mesh, map->source);
    if (!ply.ok()) return ReportError(kCommand, ply.status());
    bytes = std::move(ply->bytes);
    vertices = ply->vertices;
    faces = ply->faces;
  } else {
    absl::StatusOr<PlyExport> ply = ExportSurfacePointsPly(
        *map, choice->min_density > 0 ? static_cast<float>(choice->min_density)
                                      : kDefaultExportMinDensity);
    if (!ply.ok()) return ReportError(kCommand, ply.status());
    bytes = std::move(ply->bytes);
    vertices = ply->points;
  }
  if (absl::Status s = WriteFileAtomically(out, bytes, "export"); !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("map", flags.GetString("map")).Add("out", out);
    if (choice->mesh) {
      json.Add("vertices", vertices).Add("faces", faces);
    } else {
      json.Add("points", vertices);
    }
    json.Add("bytes", static_cast<int64_t>(bytes.size())).Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else if (choice->mesh) {
    std::cout << absl::StrFormat("wrote %s (%d vertices, %d triangles, %.1f MB)\n", out, vertices,
                                 faces, bytes.size() / 1e6);
  } else {
    std::cout << absl::StrFormat("wrote %s (%d points, %.1f MB)\n", out, vertices,
                                 bytes.size() / 1e6);
  }
  return kExitOk;
}

}  // namespace plx::cli

// What `plenox export` reports, in-process (cmd_export.cc) and on a daemon (remote_export.cc):
// the summary line and the JSON keys, written once so that the two forms cannot drift apart.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "clients/plenox/cli_common.h"
#include "core/export/map_export.h"
#include "core/geometry/axis_box.h"

namespace plx::cli {

// What was written. For a mesh, full_faces and lod_error_m say what simplification did
// (full_faces == faces: the full mesh); -1 counts are unknown (a file the client could not read
// them from).
struct ExportSummary {
  bool mesh = false;
  MeshFileFormat format = MeshFileFormat::kPly;
  int64_t vertices = 0;  // points for a point cloud
  int64_t faces = 0;
  int64_t full_faces = 0;
  double lod_error_m = 0.0;
  std::optional<AxisBox> region;  // the box the mesh was cut to (--bbox)
  uint64_t bytes = 0;
};

// "12 vertices, 20 triangles (a level of detail of 200, error 3.1 mm) in the box [0, 0, 0] ..
// [1, 1, 1], glTF" or "500 points".
std::string ExportSummaryText(const ExportSummary& summary);

// The JSON keys: points, or vertices, faces, format ("ply" / "glb"), full_faces, lod_error_m,
// with a region bbox ("xmin,ymin,zmin,xmax,ymax,zmax", as --bbox takes it); then bytes.
void AddExportSummaryJson(JsonObject& json, const ExportSummary& summary);

}  // namespace plx::cli

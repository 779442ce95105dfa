// The flags of `plenox export`, shared by the in-process command (a map file) and the remote one
// (a map on the daemon): point cloud by default, a triangle mesh with --mesh, as PLY or binary
// glTF, optionally simplified to a triangle budget (a level of detail).
#pragma once

#include "absl/status/statusor.h"
#include "app/flags.h"
#include "core/export/map_export.h"

namespace plx::cli {

// --out, --mesh, --format, --lod-triangles, --bbox, --min-density, --iso-level,
// --min-component, --max-triangles, --keep-unobserved, --mesh-color.
void AddExportFlags(FlagSet& flags);

// The spec the flags ask for, a 0 (the flags' default) read as core's default. The mesh's file
// format is --format's, else glb when --out ends in .glb, else ply. InvalidArgument (a usage
// error) for a value out of range, a flag of the other form (points or mesh), a --format that
// contradicts --out's .ply or .glb, or a --bbox that is not six numbers of a finite box with
// min < max on every axis.
absl::StatusOr<ExportSpec> ExportSpecFromFlags(const FlagSet& flags);

}  // namespace plx::cli

// The flags of `plenox export`, shared by the in-process command (a map file) and the remote one
// (a map on the daemon): point cloud by default, a triangle mesh with --mesh.
#pragma once

#include "absl/status/statusor.h"
#include "app/flags.h"
#include "core/export/map_export.h"

namespace plx::cli {

// --out, --mesh, --min-density, --iso-level, --min-component, --max-triangles,
// --keep-unobserved, --mesh-color.
void AddExportFlags(FlagSet& flags);

// The spec the flags ask for, a 0 (the flags' default) read as core's default.
// InvalidArgument (a usage error) for a value out of range or a flag of the other format.
absl::StatusOr<ExportSpec> ExportSpecFromFlags(const FlagSet& flags);

}  // namespace plx::cli

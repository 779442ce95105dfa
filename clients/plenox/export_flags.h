// The flags of `plenox export`, shared by the in-process command (a map file) and the remote one
// (a map on the daemon): point cloud by default, a triangle mesh with --mesh.
#pragma once

#include "absl/status/statusor.h"
#include "app/flags.h"
#include "core/mesh/iso_surface.h"

namespace plx::cli {

struct ExportChoice {
  bool mesh = false;
  double min_density = 0.0;  // points; 0 = the default
  MeshOptions mesh_options;  // mesh; iso_level and max_triangles resolved to the defaults
};

// --out, --mesh, --min-density, --iso-level, --min-component, --max-triangles,
// --keep-unobserved, --mesh-color.
void AddExportFlags(FlagSet& flags);

// InvalidArgument (a usage error) for a value out of range or a flag of the other format.
absl::StatusOr<ExportChoice> ExportChoiceFromFlags(const FlagSet& flags);

}  // namespace plx::cli

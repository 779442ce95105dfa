// Export's request checked and turned into the engine's options, and the PLY it asks for built
// (on a device worker: a mesh runs marching cubes on that worker's backend).
#pragma once

#include <functional>
#include <string>

#include "absl/status/statusor.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mesh/iso_surface.h"
#include "plenoxd/v1/plenoxd.pb.h"

namespace plx::server {

struct ExportSpec {
  bool mesh = false;
  float min_density = 0.0f;  // points
  MeshOptions mesh_options;  // mesh
};

// INVALID_ARGUMENT naming the field for a value out of range, an unknown enum, or a field of
// the other format set.
absl::StatusOr<ExportSpec> ParseExportRequest(const plenoxd::v1::ExportRequest& request);

// The PLY file's bytes. CANCELLED when `cancelled` says so, RESOURCE_EXHAUSTED out of memory or
// over the mesh's triangle limit, the backend's errors.
absl::StatusOr<std::string> BuildExport(const ExportSpec& spec, const PlenoxelMap& map,
                                        Backend& backend, const std::function<bool()>& cancelled);

}  // namespace plx::server

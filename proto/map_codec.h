// Maps on the wire: their names (CreateMap, Track, Integrate, Slam, Export, ...), a new map's
// voxel size (CreateMap, Slam) and MapInfo, the reply of the map RPCs.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/grid/map_status.h"
#include "proto/wire.h"

namespace plx {

// Valid map names: 1-64 characters of [A-Za-z0-9_.-], not starting with '.'.
absl::Status CheckMapName(const std::string& name, const std::string& field);

// A voxel size from a request: exactly 0 means `default_size`; anything else must lie in core's
// range [kMinVoxelSize, kMaxVoxelSize] (core/mapping/mapper.h), which also refuses negative and
// NaN sizes. INVALID_ARGUMENT "<field>: must be in [0.001, 1] metres (0 = the default), got ..."
absl::StatusOr<float> VoxelSizeFromProto(float voxel_size, float default_size,
                                         const std::string& field);

pb::MapInfo MapStatusToProto(const MapStatus& status);

}  // namespace plx

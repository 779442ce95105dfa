// plenoxd.v1 IntegrateOptions -> core/mapping: a mapping session's options for an Integrate
// stream into a map of a given voxel size.
#pragma once

#include <cstdint>

#include "absl/status/statusor.h"
#include "core/mapping/mapping_session.h"
#include "proto/wire.h"

namespace plx {

// MappingSessionOptions (kDefaultIterationsPerKeyframe) over MapperOptionsForVoxelSize(voxel_size),
// with the message's non-zero rays_per_iteration, iterations_per_keyframe and max_depth on top
// (0 means core's default), and `max_map_bytes` (--max-map-mb), checked before each keyframe's
// bricks are allocated. INVALID_ARGUMENT naming the field: "options.max_depth" (not finite or
// negative), "options.iterations_per_keyframe" (over kMaxIterationsPerKeyframe), or "options: ..."
// when ValidateMappingSessionOptions refuses the result.
absl::StatusOr<MappingSessionOptions> MappingSessionOptionsFromProto(
    const pb::IntegrateOptions& options, float voxel_size, int64_t max_map_bytes);

}  // namespace plx

// plenoxd.v1 Integrate messages <-> core/mapping: a mapping session's options for an Integrate
// stream into a map of a given voxel size (the daemon reads them, the CLI writes them), and the
// MappingProgress the stream reports.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "core/mapping/mapping_session.h"
#include "proto/wire.h"

namespace plx {

// MappingSessionOptions (kDefaultIterationsPerKeyframe) over MapperOptionsForVoxelSize(voxel_size),
// with the message's non-zero rays_per_iteration, iterations_per_keyframe and max_depth on top
// (0 means core's default), and `max_map_bytes` (--max-map-mb), checked before each keyframe's
// bricks are allocated. INVALID_ARGUMENT naming the field: "options.max_depth" (not finite or
// negative), "options.iterations_per_keyframe" (over kMaxIterationsPerKeyframe),
// "options.rays_per_iteration" (over kMaxBatchSize), or "options: ..." when
// ValidateMappingSessionOptions refuses the result (a voxel size outside core's range).
absl::StatusOr<MappingSessionOptions> MappingSessionOptionsFromProto(
    const pb::IntegrateOptions& options, float voxel_size, int64_t max_map_bytes);

// The inverse for the three settings the message carries: iterations_per_keyframe, the batch
// (rays_per_iteration) and the allocation's max_depth. The voxel size is the map's (CreateMap).
pb::IntegrateOptions IntegrateOptionsToProto(const MappingSessionOptions& options);

// An Integrate stream's progress: the session's iterations, keyframes integrated and training
// errors, with the job's id, the newest published version and the time since the stream began.
// The keyframes received and `done` are the stream's to add.
pb::MappingProgress MappingProgressToProto(const MappingSessionProgress& progress,
                                           const std::string& job_id, uint64_t map_version,
                                           double elapsed_s);

}  // namespace plx

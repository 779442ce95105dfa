// plenoxd.v1 Slam messages <-> core/slam: a stream's SlamOptions both ways (the daemon reads
// them, the CLI writes them), the SLAM state, and the updates the stream sends (SlamUpdate, with
// the map's mapping job as a SlamMapping).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "core/slam/slam_mapper.h"
#include "core/slam/slam_session.h"
#include "core/slam/slam_tracker.h"
#include "proto/track_codec.h"
#include "proto/wire.h"

namespace plx {

// The voxel size the stream asks for: options.voxel_size, where 0 is SLAM's default
// (DefaultSlamOptions). INVALID_ARGUMENT "options.voxel_size: ..." outside core's range
// [kMinVoxelSize, kMaxVoxelSize] (negative and NaN sizes too).
absl::StatusOr<float> SlamVoxelSizeFromProto(const pb::SlamOptions& options);

// SlamOptionsFor(voxel_size, the `tracking` options) with the message's non-zero keyframe and
// mapping fields on top (0 means core's default), its deterministic switch and, when present,
// its max_pending_keyframes; `max_map_bytes` (--max-map-mb) is checked before each keyframe's
// bricks are allocated. `voxel_size` is the map's (SlamVoxelSizeFromProto for a new one).
// INVALID_ARGUMENT naming the field ("options.kf_unmapped_fraction: ...") for a value outside
// its range: negative or non-finite lengths, angles, times and depths, a fraction over 1,
// iterations over kMaxIterationsPerKeyframe, rays over kMaxBatchSize, max_pending_keyframes
// over kMaxPendingKeyframes; "options.tracking..." from TrackerOptionsFromProto; "options: ..."
// for realtime with deterministic, or what ValidateSlamOptions refuses in the result.
absl::StatusOr<SlamOptions> SlamOptionsFromProto(const pb::SlamOptions& options, float voxel_size,
                                                 int64_t max_map_bytes);

// Whether the message sets any of the mapping job's settings (iterations_per_keyframe,
// rays_per_iteration, max_depth): a stream that joins a running job must then match its own.
bool SlamMappingOptionsChosen(const pb::SlamOptions& options);

// Which of a SlamOptions' settings a client chose: only those go on the wire, the others stay 0
// or absent (the daemon's defaults, which are DefaultSlamOptions' too), so that an existing
// map's voxel size or a running job's budget is not contradicted by a value nobody chose.
struct SlamOptionsFields {
  bool voxel_size = false;
  TrackOptionsFields tracking;
  bool kf_translation = false;
  bool kf_rotation = false;
  bool kf_unmapped_fraction = false;
  bool kf_interval = false;
  bool iterations_per_keyframe = false;
  bool rays_per_iteration = false;
  bool max_depth = false;
  bool max_pending_keyframes = false;
  bool loop_closure = false;
};

// The inverse of SlamOptionsFromProto for the chosen fields; the tracker's mode, `realtime`
// (latest wins, a property of the stream rather than of SLAM) and `deterministic` always.
pb::SlamOptions SlamOptionsToProto(const SlamOptions& options, bool realtime,
                                   const SlamOptionsFields& fields);

pb::SlamState SlamStateToProto(SlamState state);
// Empty for UNSPECIFIED and for numbers the proto does not declare.
std::optional<SlamState> SlamStateFromProto(pb::SlamState state);

// The map's mapping job as an update carries it: its progress (keyframes accepted and
// integrated, iterations, newest version, map bytes) with its id, the Slam streams on it and
// whether it has ended (its final version published).
pb::SlamMapping SlamMappingToProto(const SlamMapperProgress& progress, const std::string& job_id,
                                   int streams, bool finished);

// A loop closure's correction as a stream sends it: every keyframe before and after, and how
// this camera moved with it (SlamFrameResult::frame_change); and back, for a client to move
// what it holds (SlamCorrection::Move; camera_new_T_old is the update's to read).
pb::SlamCorrection SlamCorrectionToProto(const SlamCorrection& correction,
                                         const SE3& camera_new_T_old);
// (InvalidArgument: a pose that is not one).
absl::StatusOr<SlamCorrection> SlamCorrectionFromProto(const pb::SlamCorrection& wire);

// A tracked frame's update: the result's timestamp, pose, state, reason, keyframe flag, map
// version and valid rays, with what the stream knows: the frame's 0-based index in the stream,
// the time from receiving it (latency_ms), the frames dropped since the previous update and the
// mapping job as the update is sent.
pb::SlamUpdate SlamUpdateToProto(const SlamFrameResult& result, uint32_t frame, double latency_ms,
                                 uint32_t dropped, pb::SlamMapping mapping);

// The stream's last message (`done`, no frame fields) with the mapping job's final state.
pb::SlamUpdate SlamDoneToProto(pb::SlamMapping mapping);

}  // namespace plx

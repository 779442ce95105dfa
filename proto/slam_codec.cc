#include "proto/slam_codec.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mapping/mapper.h"
#include "core/mapping/mapping_session.h"
#include "proto/map_codec.h"
#include "proto/pose_codec.h"

namespace plx {
namespace {

absl::Status Invalid(const char* field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("options.", field, ": ", what));
}

// A length, angle, time or depth: finite and >= 0, 0 meaning the default.
absl::Status CheckOptional(double value, const char* field) {
  if (std::isfinite(value) && value >= 0.0) return absl::OkStatus();
  return Invalid(field, absl::StrCat("must be finite and >= 0 (0 = the default), got ", value));
}

// The keyframe policy's thresholds (KeyframePolicy; degrees on the wire, radians in core).
absl::Status ApplyKeyframeFields(const pb::SlamOptions& o, KeyframePolicy& policy) {
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_translation_m(), "kf_translation_m"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_rotation_deg(), "kf_rotation_deg"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_unmapped_fraction(), "kf_unmapped_fraction"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_interval_s(), "kf_interval_s"));
  if (o.kf_unmapped_fraction() > 1.0f) {
    return Invalid("kf_unmapped_fraction", absl::StrCat("a fraction of the view, at most 1, got ",
                                                        o.kf_unmapped_fraction()));
  }
  if (o.kf_translation_m() > 0) policy.max_translation_m = o.kf_translation_m();
  if (o.kf_rotation_deg() > 0) policy.max_rotation_rad = o.kf_rotation_deg() * M_PI / 180.0;
  if (o.kf_unmapped_fraction() > 0) policy.max_unmapped_fraction = o.kf_unmapped_fraction();
  if (o.kf_interval_s() > 0) policy.max_interval_s = o.kf_interval_s();
  if (absl::Status s = ValidateKeyframePolicy(policy); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", s.message()));
  }
  return absl::OkStatus();
}

// The mapping job's settings (the first stream's, SlamJob).
absl::Status ApplyMappingFields(const pb::SlamOptions& o, MappingSessionOptions& mapping) {
  PLX_RETURN_IF_ERROR(CheckOptional(o.max_depth(), "max_depth"));
  if (o.iterations_per_keyframe() > static_cast<uint32_t>(kMaxIterationsPerKeyframe)) {
    return Invalid("iterations_per_keyframe", absl::StrCat("at most ", kMaxIterationsPerKeyframe));
  }
  if (o.rays_per_iteration() > static_cast<uint32_t>(kMaxBatchSize)) {
    return Invalid("rays_per_iteration", absl::StrCat("at most ", kMaxBatchSize));
  }
  if (o.iterations_per_keyframe() > 0) {
    mapping.iterations_per_keyframe = static_cast<int>(o.iterations_per_keyframe());
  }
  if (o.rays_per_iteration() > 0) {
    mapping.mapper.batch_size = static_cast<int>(o.rays_per_iteration());
  }
  if (o.max_depth() > 0) {
    mapping.mapper.allocation.max_depth = o.max_depth();
    mapping.mapper.fusion.max_depth = o.max_depth();
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<float> SlamVoxelSizeFromProto(const pb::SlamOptions& options) {
  return VoxelSizeFromProto(options.voxel_size(), DefaultSlamOptions().mapping.mapper.voxel_size,
                            "options.voxel_size");
}

absl::StatusOr<SlamOptions> SlamOptionsFromProto(const pb::SlamOptions& o, float voxel_size,
                                                 int64_t max_map_bytes) {
  PLX_ASSIGN_OR_RETURN(const TrackerOptions tracker,
                       TrackerOptionsFromProto(o.tracking(), "options.tracking"));
  SlamOptions s = SlamOptionsFor(voxel_size, tracker);
  PLX_RETURN_IF_ERROR(ApplyKeyframeFields(o, s.keyframes));
  PLX_RETURN_IF_ERROR(ApplyMappingFields(o, s.mapping));
  s.mapping.mapper.max_map_bytes = max_map_bytes;
  if (o.realtime() && o.deterministic()) {
    return absl::InvalidArgumentError(
        "options: realtime and deterministic exclude each other (lock-step waits for mapping)");
  }
  s.deterministic = o.deterministic();
  s.live_source = o.realtime();
  s.loop_closure.enabled = !o.has_loop_closure() || o.loop_closure();
  if (o.has_max_pending_keyframes()) {
    if (o.max_pending_keyframes() > static_cast<uint32_t>(kMaxPendingKeyframes)) {
      return Invalid("max_pending_keyframes", absl::StrCat("must be in [0, ", kMaxPendingKeyframes,
                                                           "], got ", o.max_pending_keyframes()));
    }
    s.max_pending_keyframes = static_cast<int>(o.max_pending_keyframes());
    // The default is ignored in lock-step; a bound asked for with it is a contradiction.
    if (s.deterministic && s.max_pending_keyframes > 0) {
      return absl::InvalidArgumentError(
          "options: max_pending_keyframes must be 0 with deterministic (lock-step waits for "
          "each keyframe's mapping)");
    }
  }
  // The rest (the voxel size, the options' ranges, ...) is core's to check.
  if (absl::Status st = ValidateSlamOptions(s); !st.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", st.message()));
  }
  return s;
}

bool SlamMappingOptionsChosen(const pb::SlamOptions& o) {
  return o.iterations_per_keyframe() > 0 || o.rays_per_iteration() > 0 || o.max_depth() > 0;
}

pb::SlamOptions SlamOptionsToProto(const SlamOptions& s, bool realtime,
                                   const SlamOptionsFields& fields) {
  pb::SlamOptions wire;
  if (fields.voxel_size) wire.set_voxel_size(s.mapping.mapper.voxel_size);
  *wire.mutable_tracking() = TrackOptionsToProto(s.tracker, fields.tracking);
  if (fields.kf_translation) {
    wire.set_kf_translation_m(static_cast<float>(s.keyframes.max_translation_m));
  }
  if (fields.kf_rotation) {
    wire.set_kf_rotation_deg(static_cast<float>(s.keyframes.max_rotation_rad * 180.0 / M_PI));
  }
  if (fields.kf_unmapped_fraction) {
    wire.set_kf_unmapped_fraction(static_cast<float>(s.keyframes.max_unmapped_fraction));
  }
  if (fields.kf_interval) wire.set_kf_interval_s(static_cast<float>(s.keyframes.max_interval_s));
  if (fields.iterations_per_keyframe) {
    wire.set_iterations_per_keyframe(static_cast<uint32_t>(s.mapping.iterations_per_keyframe));
  }
  if (fields.rays_per_iteration) {
    wire.set_rays_per_iteration(static_cast<uint32_t>(s.mapping.mapper.batch_size));
  }
  if (fields.max_depth) wire.set_max_depth(s.mapping.mapper.allocation.max_depth);
  if (fields.max_pending_keyframes) {
    wire.set_max_pending_keyframes(static_cast<uint32_t>(s.max_pending_keyframes));
  }
  wire.set_realtime(realtime);
  wire.set_deterministic(s.deterministic);
  if (fields.loop_closure) wire.set_loop_closure(s.loop_closure.enabled);
  return wire;
}

pb::SlamState SlamStateToProto(SlamState state) {
  switch (state) {
    case SlamState::kOk: return pb::SLAM_STATE_OK;
    case SlamState::kDegraded: return pb::SLAM_STATE_DEGRADED;
    case SlamState::kLost: return pb::SLAM_STATE_LOST;
    case SlamState::kRelocalised: return pb::SLAM_STATE_RELOCALISED;
    case SlamState::kWaiting: return pb::SLAM_STATE_WAITING;
  }
  return pb::SLAM_STATE_UNSPECIFIED;
}

std::optional<SlamState> SlamStateFromProto(pb::SlamState state) {
  switch (state) {
    case pb::SLAM_STATE_OK: return SlamState::kOk;
    case pb::SLAM_STATE_DEGRADED: return SlamState::kDegraded;
    case pb::SLAM_STATE_LOST: return SlamState::kLost;
    case pb::SLAM_STATE_RELOCALISED: return SlamState::kRelocalised;
    case pb::SLAM_STATE_WAITING: return SlamState::kWaiting;
    default: return std::nullopt;
  }
}

pb::SlamMapping SlamMappingToProto(const SlamMapperProgress& p, const std::string& job_id,
                                   int streams, bool finished) {
  pb::SlamMapping mapping;
  mapping.set_job_id(job_id);
  mapping.set_keyframes(static_cast<uint32_t>(p.keyframes));
  mapping.set_keyframes_integrated(static_cast<uint32_t>(p.keyframes_integrated));
  mapping.set_iterations(static_cast<uint32_t>(p.mapping_iterations));
  mapping.set_map_version(static_cast<uint64_t>(p.map_version));
  mapping.set_map_bytes(static_cast<uint64_t>(p.map_bytes));
  mapping.set_streams(static_cast<uint32_t>(streams));
  mapping.set_finished(finished);
  mapping.set_loops_accepted(static_cast<uint32_t>(p.loops.accepted));
  mapping.set_loops_rejected(static_cast<uint32_t>(p.loops.rejected));
  mapping.set_corrections(static_cast<uint32_t>(p.loops.corrections));
  mapping.set_corrections_in_place(static_cast<uint32_t>(p.loops.in_place));
  mapping.set_last_solve_ms(p.loops.last_solve_ms);
  return mapping;
}

pb::SlamCorrection SlamCorrectionToProto(const SlamCorrection& c, const SE3& camera_new_T_old) {
  pb::SlamCorrection wire;
  wire.set_generation(static_cast<uint32_t>(c.generation));
  wire.set_map_version(static_cast<uint64_t>(c.map_version));
  PoseToProto(camera_new_T_old, wire.mutable_camera_new_t_old());
  // Every keyframe, the unmoved ones too: a client anchors a pose to the keyframe the daemon
  // would (SlamCorrection::NearestKeyframe), which needs them all.
  const size_t n = std::min(c.before.size(), c.after.size());
  for (size_t i = 0; i < n; ++i) {
    pb::KeyframeMove* move = wire.add_keyframes();
    PoseToProto(c.before[i], move->mutable_before());
    PoseToProto(c.after[i], move->mutable_after());
  }
  wire.set_max_shift_m(c.max_shift_m);
  wire.set_loops(static_cast<uint32_t>(c.loops));
  return wire;
}

absl::StatusOr<SlamCorrection> SlamCorrectionFromProto(const pb::SlamCorrection& wire) {
  SlamCorrection c;
  c.generation = static_cast<int>(wire.generation());
  c.map_version = static_cast<int64_t>(wire.map_version());
  for (const pb::KeyframeMove& move : wire.keyframes()) {
    PLX_ASSIGN_OR_RETURN(SE3 before, PoseFromProto(move.before(), "correction.keyframes.before"));
    PLX_ASSIGN_OR_RETURN(SE3 after, PoseFromProto(move.after(), "correction.keyframes.after"));
    c.before.push_back(before);
    c.after.push_back(after);
  }
  c.max_shift_m = wire.max_shift_m();
  c.loops = static_cast<int>(wire.loops());
  return c;
}

pb::SlamUpdate SlamUpdateToProto(const SlamFrameResult& result, uint32_t frame, double latency_ms,
                                 uint32_t dropped, pb::SlamMapping mapping) {
  pb::SlamUpdate update;
  update.set_frame(frame);
  update.set_timestamp(result.timestamp);
  PoseToProto(result.pose, update.mutable_pose());
  update.set_state(SlamStateToProto(result.state));
  update.set_reason(result.reason);
  update.set_keyframe(result.keyframe);
  update.set_map_version(static_cast<uint64_t>(result.map_version));
  update.set_latency_ms(latency_ms);
  update.set_dropped(dropped);
  update.set_valid_rays(static_cast<uint32_t>(result.tracking.valid_rays));
  update.set_segment(static_cast<uint32_t>(result.segment));
  update.set_new_segment(result.new_segment);
  if (result.main_T_segment) PoseToProto(*result.main_T_segment, update.mutable_main_t_segment());
  update.set_correction_generation(static_cast<uint32_t>(result.correction_generation));
  if (result.correction != nullptr) {
    *update.mutable_correction() = SlamCorrectionToProto(*result.correction, result.frame_change);
  }
  *update.mutable_mapping() = std::move(mapping);
  return update;
}

pb::SlamUpdate SlamDoneToProto(pb::SlamMapping mapping) {
  pb::SlamUpdate done;
  done.set_done(true);
  *done.mutable_mapping() = std::move(mapping);
  return done;
}

}  // namespace plx

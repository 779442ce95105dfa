#include "server/slam_reactor.h"

#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "core/slam/slam_session.h"
#include "proto/track_codec.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {
namespace {

pb::SlamState ToProto(SlamState state) {
  switch (state) {
    case SlamState::kOk: return pb::SLAM_STATE_OK;
    case SlamState::kDegraded: return pb::SLAM_STATE_DEGRADED;
    case SlamState::kLost: return pb::SLAM_STATE_LOST;
    case SlamState::kRelocalised: return pb::SLAM_STATE_RELOCALISED;
    case SlamState::kWaiting: return pb::SLAM_STATE_WAITING;
  }
  return pb::SLAM_STATE_UNSPECIFIED;
}

void MappingToProto(const SlamJobStatus& s, pb::SlamMapping* out) {
  out->set_job_id(s.job_id);
  out->set_keyframes(static_cast<uint32_t>(s.mapping.keyframes));
  out->set_keyframes_integrated(static_cast<uint32_t>(s.mapping.keyframes_integrated));
  out->set_iterations(static_cast<uint32_t>(s.mapping.mapping_iterations));
  out->set_map_version(static_cast<uint64_t>(s.mapping.map_version));
  out->set_map_bytes(static_cast<uint64_t>(s.mapping.map_bytes));
  out->set_streams(static_cast<uint32_t>(s.streams));
  out->set_finished(s.finished);
}

// A non-negative finite number, 0 meaning the default.
absl::Status CheckOptional(double value, const char* field) {
  if (std::isfinite(value) && value >= 0.0) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat("options.", field, ": must be finite and >= 0 (0 = the default), got ", value));
}

// The stream's options on top of SLAM's defaults at the map's voxel size (core/slam).
absl::StatusOr<SlamOptions> SlamOptionsFromProto(const pb::SlamOptions& o, float voxel_size,
                                                 int64_t max_map_bytes) {
  PLX_ASSIGN_OR_RETURN(const TrackerOptions tracker,
                       TrackerOptionsFromProto(o.tracking(), "options.tracking"));
  SlamOptions s = SlamOptionsFor(voxel_size, tracker);
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_translation_m(), "kf_translation_m"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_rotation_deg(), "kf_rotation_deg"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_unmapped_fraction(), "kf_unmapped_fraction"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.kf_interval_s(), "kf_interval_s"));
  PLX_RETURN_IF_ERROR(CheckOptional(o.max_depth(), "max_depth"));
  if (o.kf_translation_m() > 0) s.keyframes.max_translation_m = o.kf_translation_m();
  if (o.kf_rotation_deg() > 0) s.keyframes.max_rotation_rad = o.kf_rotation_deg() * M_PI / 180.0;
  if (o.kf_unmapped_fraction() > 0) s.keyframes.max_unmapped_fraction = o.kf_unmapped_fraction();
  if (o.kf_interval_s() > 0) s.keyframes.max_interval_s = o.kf_interval_s();
  if (absl::Status st = ValidateKeyframePolicy(s.keyframes); !st.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", st.message()));
  }
  if (o.iterations_per_keyframe() > static_cast<uint32_t>(kMaxIterationsPerKeyframe)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.iterations_per_keyframe: at most ", kMaxIterationsPerKeyframe));
  }
  if (o.iterations_per_keyframe() > 0) {
    s.mapping.iterations_per_keyframe = static_cast<int>(o.iterations_per_keyframe());
  }
  if (o.rays_per_iteration() > 0) {
    s.mapping.mapper.batch_size = static_cast<int>(o.rays_per_iteration());
  }
  if (o.max_depth() > 0) {
    s.mapping.mapper.allocation.max_depth = o.max_depth();
    s.mapping.mapper.fusion.max_depth = o.max_depth();
  }
  // --max-map-mb is checked before each keyframe's bricks are allocated.
  s.mapping.mapper.max_map_bytes = max_map_bytes;
  if (o.realtime() && o.deterministic()) {
    return absl::InvalidArgumentError(
        "options: realtime and deterministic exclude each other (lock-step waits for mapping)");
  }
  s.deterministic = o.deterministic();
  if (o.has_max_pending_keyframes()) {
    // Checked with the rest below (ValidateSlamOptions: range, lock-step); a value past int's
    // range becomes negative here and is refused there.
    s.max_pending_keyframes = static_cast<int>(o.max_pending_keyframes());
  }
  if (absl::Status st = ValidateSlamOptions(s); !st.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", st.message()));
  }
  return s;
}

}  // namespace

SlamReactor::SlamReactor(DaemonState* state, grpc::CallbackServerContext* context)
    : StreamReactor(state, context, "Slam", "SlamRequest") {}

SlamReactor::~SlamReactor() {
  // First: a notification in progress finishes before the members it reaches go away.
  if (listener_) listener_->Reset();
  if (job_ != nullptr && camera_ >= 0) job_->trajectory().Close(camera_);
}

absl::Status SlamReactor::HandleFirstMessage() {
  const pb::SlamOptions& o = request_.options();
  if (!std::isfinite(o.voxel_size()) || o.voxel_size() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.voxel_size: must be finite and >= 0 (0 = the default), got ", o.voxel_size()));
  }
  // The options and the initial pose are checked before the store is touched (a refused
  // stream creates no map, which would count against --max-maps); the lengths that scale with
  // the voxel size are set again at the map's own below.
  // 0 = SLAM's default voxel size (the proto's 0.02 m), for a new map and for these checks.
  const float voxel_size =
      o.voxel_size() > 0 ? o.voxel_size() : DefaultSlamOptions().mapping.mapper.voxel_size;
  PLX_RETURN_IF_ERROR(
      SlamOptionsFromProto(o, voxel_size, state_->maps->max_map_bytes()).status());
  std::optional<SE3> initial_pose;
  if (request_.has_initial_pose()) {
    PLX_ASSIGN_OR_RETURN(initial_pose, PoseFromProto(request_.initial_pose(), "initial_pose"));
    PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(*initial_pose, "initial_pose"));
  }
  // A map that does not exist yet is created here; another stream may create it meanwhile.
  absl::StatusOr<MapStatus> info = state_->maps->Info(map_name_);
  if (absl::IsNotFound(info.status())) {
    info = state_->maps->Create(map_name_, voxel_size);
    if (absl::IsAlreadyExists(info.status())) info = state_->maps->Info(map_name_);
  }
  if (!info.ok()) return info.status();
  if (o.voxel_size() > 0 && std::fabs(o.voxel_size() - info->voxel_size) > 1e-7f) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "options.voxel_size: map \"%s\" has voxel size %g, got %g", map_name_, info->voxel_size,
        o.voxel_size()));
  }
  PLX_ASSIGN_OR_RETURN(
      const SlamOptions slam,
      SlamOptionsFromProto(o, info->voxel_size, state_->maps->max_map_bytes()));
  const SlamSplitOptions split = SplitSlamOptions(slam);
  tracker_options_ = split.tracker;
  if (initial_pose) tracker_options_.initial_pose = initial_pose;
  realtime_ = o.realtime();
  max_pending_keyframes_ = split.gate.max_pending_keyframes;
  const bool mapping_set =
      o.iterations_per_keyframe() > 0 || o.rays_per_iteration() > 0 || o.max_depth() > 0;
  listener_ = std::make_shared<SlamJobListener>([this] { OnJobChanged(); });
  PLX_ASSIGN_OR_RETURN(job_, state_->slam_jobs->Join(map_name_, split, mapping_set, listener_));
  state_->metrics->slam_streams++;
  camera_ = job_->trajectory().AddCamera();
  LogEvent("info", "slam_stream_joined",
           {{"map", map_name_}, {"job", job_->Status().job_id},
            {"streams", absl::StrCat(job_->Status().streams)}});
  return absl::OkStatus();
}

absl::Status SlamReactor::HandleRequestLocked(bool first) {
  if (first) PLX_RETURN_IF_ERROR(HandleFirstMessage());
  if (request_.has_frame() && state_->draining) {
    // The daemon stops: no more frames; the ones accepted are processed, their keyframes
    // integrated and the map saved, and the stream ends with its done message.
    LogEvent("info", "slam_input_ended", {{"map", map_name_}, {"reason", "draining"}});
    EndInputLocked();
    return absl::OkStatus();
  }
  if (request_.has_frame()) {
    // Its position in the stream, counting every frame received: the ones tracked, the one
    // being tracked, those queued and those dropped.
    const uint32_t index = received_++;
    const std::string field = absl::StrCat("frame[", index, "]");
    PLX_ASSIGN_OR_RETURN(CheckedFrame frame,
                         CheckFrame(std::move(*request_.mutable_frame()), field, false,
                                    state_->config.max_frame_pixels));
    if (frame.client_pose) {
      PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(*frame.client_pose, field + ".pose"));
    }
    if (realtime_ && !queue_.empty()) {
      // Latest wins: the frame still waiting is stale now.
      queue_.clear();
      ++dropped_;
      state_->metrics->frames_dropped++;
    }
    queue_.push_back(Pending{std::move(frame), index, std::chrono::steady_clock::now()});
    AdvanceLocked();
  }
  return absl::OkStatus();
}

void SlamReactor::OnInputClosedLocked() { AdvanceLocked(); }

bool SlamReactor::JobAllowsNextFrameLocked() {
  if (!wait_for_job_) return true;
  const SlamJobStatus s = job_->Status();
  if (!s.error.ok() || s.finished) return true;  // the task reports it
  // The map's rule (SlamCoordinator::MayCameraProceed) with this stream's bound.
  const bool ready = job_->MayCameraProceed(max_pending_keyframes_);
  if (ready) wait_for_job_ = false;
  return ready;
}

void SlamReactor::AdvanceLocked() {
  if (finished() || busy() || job_ == nullptr) return;
  if (failed()) {
    MaybeFinishLocked();
    return;
  }
  if (!queue_.empty()) {
    if (!JobAllowsNextFrameLocked()) return;  // OnJobChanged calls back
    PostLocked(Priority::kInteractive,
               [this](Backend* backend, bool cancelled) { RunTask(backend, cancelled); });
    return;
  }
  if (open()) return;
  // Input over, every frame processed: leave the job; the last stream waits for its end.
  LeaveJobLocked();
  if (done_sent_) return;
  const SlamJobStatus s = job_->Status();
  if (!s.error.ok()) {
    FailLocked(s.error);
    return;
  }
  // The last stream waits for the job to finish the map (OnJobChanged); with others still on
  // it, mapping goes on for them.
  if (!s.finished && s.streams == 0) return;
  pb::SlamUpdate done;
  done.set_done(true);
  MappingToProto(s, done.mutable_mapping());
  done_sent_ = true;
  WriteLocked(std::move(done));
  MaybeFinishLocked();
}

void SlamReactor::OnJobChanged() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished()) return;
  const SlamJobStatus s = job_->Status();
  if (!s.error.ok()) {
    FailLocked(s.error);
    return;
  }
  AdvanceLocked();
}

void SlamReactor::LeaveJobLocked() {
  if (left_job_ || job_ == nullptr) return;
  left_job_ = true;
  job_->Leave(listener_);
  job_->trajectory().Close(camera_);
  state_->metrics->slam_streams--;
}

void SlamReactor::RunTask(Backend* backend, bool cancelled) {
  std::optional<Pending> work;
  std::shared_ptr<SlamJob> job;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!StartTaskLocked(cancelled)) return;
    work = std::move(queue_.front());
    queue_.pop_front();
    job = job_;
    ResumeReadingLocked();
  }
  pb::SlamUpdate update;
  bool client_error = false;  // the frame's data was bad: no error log, the stream just ends
  bool retry = false;         // the map has no version yet: the frame waits for it
  SlamFrameResult result;
  std::string camera_label;  // the frame's camera_id, for the viewer
  const absl::Status failure = CatchAllocationFailure("SLAM tracking", [&]() -> absl::Status {
    const SlamMapView view = job->View();
    if (!tracker_) tracker_ = std::make_unique<SlamTracker>(tracker_options_, backend);
    // Only a bootstrap candidate (no keyframe in the map yet, from a camera that has not
    // tracked a frame: the first frame, or one after WAITING frames, of any camera on the map)
    // tracks without a version; any other waits for one, still encoded (SlamTracker::Track's
    // precondition, checked before the frame is decoded or moved).
    if (tracker_->NeedsVersion(view)) {
      retry = true;
      return absl::OkStatus();
    }
    absl::StatusOr<DecodedFrame> decoded = DecodeCheckedFrame(std::move(work->frame));
    if (!decoded.ok()) {
      client_error = decoded.status().code() == absl::StatusCode::kInvalidArgument;
      return decoded.status();
    }
    const RgbdFrame& frame = decoded->frame;
    const PinholeIntrinsics& k = decoded->calibration.pinhole;
    camera_label = decoded->camera_id;
    if (absl::Status s = tracker_->CheckFrame(frame, k, decoded->client_pose); !s.ok()) {
      client_error = true;
      return s;
    }
    absl::StatusOr<SlamFrameResult> tracked =
        tracker_->Track(frame, k, decoded->client_pose, view);
    if (!tracked.ok()) return tracked.status();  // the backend's (memory, device)
    result = *std::move(tracked);
    if (result.keyframe) PLX_RETURN_IF_ERROR(job->AddKeyframe(frame, result.pose, k));
    return absl::OkStatus();
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - work->received).count();

  std::lock_guard<std::mutex> lock(mutex_);
  TaskDoneLocked();
  if (!failure.ok()) {
    if (!client_error) {
      LogEvent("error", "slam_failed", {{"map", map_name_}, {"error", failure.ToString()}});
    }
    FailLocked(failure);
    return;
  }
  if (finished()) return;
  if (retry) {
    queue_.push_front(*std::move(work));
    wait_for_job_ = true;
    AdvanceLocked();
    return;
  }
  job_->trajectory().Record(camera_, camera_label, result.timestamp, result.pose, result.state);
  ++processed_;
  update.set_frame(work->index);
  update.set_timestamp(result.timestamp);
  PoseToProto(result.pose, update.mutable_pose());
  update.set_state(ToProto(result.state));
  update.set_reason(result.reason);
  update.set_keyframe(result.keyframe);
  update.set_map_version(static_cast<uint64_t>(result.map_version));
  update.set_latency_ms(1000.0 * seconds);
  update.set_dropped(dropped_);
  dropped_ = 0;
  update.set_valid_rays(static_cast<uint32_t>(result.tracking.valid_rays));
  MappingToProto(job_->Status(), update.mutable_mapping());
  state_->metrics->ObserveSlamFrame(static_cast<int>(result.state), seconds);
  if (result.keyframe) {
    ++keyframes_;
    wait_for_job_ = true;
    state_->metrics->slam_keyframes++;
  }
  if (result.keyframe) {
    LogEvent("info", "slam_keyframe",
             {{"map", map_name_}, {"frame", absl::StrCat(work->index)},
              {"keyframes", absl::StrCat(update.mapping().keyframes())},
              {"reason", result.reason}});
  }
  if (!last_state_ || *last_state_ != result.state) {
    LogEvent(result.state == SlamState::kLost ? "warning" : "info", "slam_state",
             {{"map", map_name_}, {"frame", absl::StrCat(work->index)},
              {"state", SlamStateName(result.state)}, {"reason", result.reason}});
    last_state_ = result.state;
  }
  WriteLocked(std::move(update));
  AdvanceLocked();
}

void SlamReactor::OnFailedLocked(const absl::Status&) {
  queue_.clear();
  LeaveJobLocked();
}

std::vector<LogField> SlamReactor::LogFields() const {
  return {{"map", map_name_},
          {"frames", absl::StrCat(processed_)},
          {"keyframes", absl::StrCat(keyframes_)}};
}

}  // namespace plx::server

#include "server/slam_reactor.h"

#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "core/slam/slam_session.h"
#include "proto/slam_codec.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {
namespace {

// The job's mapping as an update carries it.
pb::SlamMapping MappingToProto(const SlamJobStatus& s) {
  return SlamMappingToProto(s.mapping, s.job_id, s.streams, s.finished);
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
  // The options and the initial pose are checked before the store is touched (a refused
  // stream creates no map, which would count against --max-maps); the lengths that scale with
  // the voxel size are set again at the map's own below. The voxel size asked for (SLAM's
  // default for 0) is a new map's, and the one these checks use.
  PLX_ASSIGN_OR_RETURN(const float voxel_size, SlamVoxelSizeFromProto(o));
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
  const bool mapping_set = SlamMappingOptionsChosen(o);
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
  const bool ready = job_->MayCameraProceed(max_pending_keyframes_, segment_, needs_version_);
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
  done_sent_ = true;
  pb::SlamUpdate done = SlamDoneToProto(MappingToProto(s));
  if (processed_ > 0 && last_segment_ == 0) {
    // What the map corrected after the last frame reaches the client here or never.
    const std::vector<std::shared_ptr<const SlamCorrection>> after =
        job_->CorrectionsAfter(last_generation_);
    const std::vector<SE3> changes = FrameChangesAlong(after, last_pose_);
    for (size_t i = 0; i < after.size(); ++i) {
      *done.add_corrections_after() = SlamCorrectionToProto(*after[i], changes[i]);
    }
  }
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
  int segment = 0;
  int camera = -1;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!StartTaskLocked(cancelled)) return;
    work = std::move(queue_.front());
    queue_.pop_front();
    job = job_;
    segment = segment_;
    camera = camera_;
    ResumeReadingLocked();
  }
  bool client_error = false;  // the frame's data was bad: no error log, the stream just ends
  bool retry = false;         // the map has no version yet: the frame waits for it
  SlamFrameResult result;
  std::string camera_label;  // the frame's camera_id, for the viewer
  const absl::Status failure = CatchAllocationFailure("SLAM tracking", [&]() -> absl::Status {
    const SlamMapView view = job->View(segment);
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
    PLX_RETURN_IF_ERROR(job->Accept(frame, k, &result, &segment, camera));
    return absl::OkStatus();
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - work->received).count();

  // What the next frame waits for (JobAllowsNextFrameLocked): a version unless the odometry
  // carries the camera.
  const bool needs_version = tracker_ == nullptr || !tracker_->CarriesWithoutMap();
  std::lock_guard<std::mutex> lock(mutex_);
  TaskDoneLocked();
  segment_ = segment;
  needs_version_ = needs_version;
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
  last_pose_ = result.pose;
  last_segment_ = result.segment;
  last_generation_ = result.correction_generation;
  pb::SlamUpdate update = SlamUpdateToProto(result, work->index, 1000.0 * seconds, dropped_,
                                            MappingToProto(job_->Status()));
  dropped_ = 0;
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

#include "server/integrate_reactor.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "core/mapping/map_keyframes_of.h"
#include "proto/integrate_codec.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

IntegrateReactor::IntegrateReactor(DaemonState* state, grpc::CallbackServerContext* context)
    : StreamReactor(state, context, "Integrate", "IntegrateRequest") {}

absl::Status IntegrateReactor::HandleFirstMessage() {
  absl::StatusOr<MapStatus> info = state_->maps->Info(map_name_);
  if (!info.ok()) return info.status();
  // --max-map-mb is checked before each keyframe's bricks are allocated, not only at publish.
  PLX_ASSIGN_OR_RETURN(options_,
                       MappingSessionOptionsFromProto(request_.options(), info->voxel_size,
                                                      state_->maps->max_map_bytes()));
  PLX_RETURN_IF_ERROR(state_->maps->BeginMapping(map_name_, MappingJobKind::kIntegrate));
  lease_ = true;
  job_id_ = state_->jobs->Create("integrate", map_name_);
  state_->jobs->Update(job_id_, JobState::kRunning, 0.0, "waiting for keyframes");
  start_ = std::chrono::steady_clock::now();
  LogEvent("info", "mapping_started", {{"map", map_name_}, {"job", job_id_}});
  return absl::OkStatus();
}

absl::Status IntegrateReactor::HandleRequestLocked(bool first) {
  if (first) PLX_RETURN_IF_ERROR(HandleFirstMessage());
  if (request_.has_frame()) {
    const std::string field = absl::StrCat("frame[", received_, "]");
    PLX_ASSIGN_OR_RETURN(CheckedFrame frame,
                         CheckFrame(std::move(*request_.mutable_frame()), field, true,
                                    state_->config.max_frame_pixels));
    // Core refuses such a keyframe too; checked here to name the field.
    PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(*frame.client_pose, field + ".pose"));
    queue_.push_back(std::move(frame));
    ++received_;
    ScheduleLocked();
  }
  return absl::OkStatus();
}

void IntegrateReactor::OnInputClosedLocked() {
  if (lease_) ScheduleLocked();  // spend the rest of the budget, then finish
}

void IntegrateReactor::ScheduleLocked() {
  if (busy()) return;
  PostLocked(Priority::kBackground,
             [this](Backend* backend, bool cancelled) { RunTask(backend, cancelled); });
}

void IntegrateReactor::RunTask(Backend* backend, bool cancelled) {
  std::deque<CheckedFrame> frames;
  bool input_closed = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!StartTaskLocked(cancelled)) return;
    // One keyframe per task into the session (it integrates one per step), so the frames
    // waiting stay bounded by kMaxQueuedKeyframes (backpressure on the client), and only the
    // one being integrated is ever decoded.
    if (!queue_.empty()) {
      frames.push_back(std::move(queue_.front()));
      queue_.pop_front();
    }
    input_closed = !open() && queue_.empty();
    ResumeReadingLocked();
  }
  // The mapping policy (budget, chunking, publishing) is the session's (core/mapping); this
  // task only moves keyframes in and versions out.
  const auto task_start = std::chrono::steady_clock::now();
  bool client_error = false;  // a keyframe's data was bad: the stream ends, no error log
  MappingStepResult step;
  // Out of memory anywhere in the step fails this job with RESOURCE_EXHAUSTED; it must not
  // escape into the worker thread.
  const absl::Status status = CatchAllocationFailure("mapping", [&]() -> absl::Status {
    if (!session_) {
      PLX_ASSIGN_OR_RETURN(const MapVersion latest, state_->maps->Latest(map_name_));
      PLX_ASSIGN_OR_RETURN(session_, MappingSession::Create(options_, backend, latest.map));
      base_keyframes_ = latest.keyframes;
    }
    for (CheckedFrame& f : frames) {
      absl::StatusOr<DecodedFrame> decoded = DecodeCheckedFrame(std::move(f));
      if (!decoded.ok()) {
        client_error = decoded.status().code() == absl::StatusCode::kInvalidArgument;
        return decoded.status();
      }
      const SE3 pose = *decoded->client_pose;
      PLX_RETURN_IF_ERROR(
          session_->AddKeyframe(std::move(decoded->frame), pose, decoded->calibration.pinhole));
    }
    PLX_ASSIGN_OR_RETURN(step, session_->Step(/*finish=*/input_closed));
    state_->metrics->keyframes_integrated += step.keyframes_integrated;
    if (step.published) {
      PLX_ASSIGN_OR_RETURN(version_, state_->maps->Publish(map_name_, step.published,
                                                           step.keyframes_in_published,
                                                           PublishedKeyframes()));
    }
    return absl::OkStatus();
  });

  // Every tracking frame on this worker waits for a task in progress: say when one was long.
  if (const double task_s = SecondsSince(task_start); task_s > kSlowTaskSeconds) {
    LogEvent("warning", "slow_mapping_task",
             {{"map", map_name_}, {"job", job_id_}, {"seconds", absl::StrFormat("%.3f", task_s)},
              {"integrate_s", absl::StrFormat("%.3f", step.integrate_s)},
              {"optimize_s", absl::StrFormat("%.3f", step.optimize_s)},
              {"publish_s", absl::StrFormat("%.3f", step.publish_s)}});
  }
  const MappingSessionProgress p = session_ ? session_->progress() : MappingSessionProgress();
  const bool finishing = input_closed && session_ != nullptr && !session_->has_work();
  pb::MappingProgress progress = MappingProgressToProto(p, job_id_, version_, SecondsSince(start_));
  integrated_ = p.keyframes_integrated;

  std::lock_guard<std::mutex> lock(mutex_);
  TaskDoneLocked();
  progress.set_keyframes_received(received_);
  if (!status.ok()) {
    if (!client_error) {
      LogEvent("error", "mapping_failed",
               {{"map", map_name_}, {"job", job_id_}, {"error", status.ToString()}});
    }
    FailLocked(status);
    return;
  }
  if (finished()) return;
  if ((finishing && queue_.empty()) || (input_closed && session_ == nullptr)) {
    progress.set_done(true);
    done_sent_ = true;
    WriteLocked(std::move(progress));  // the final message is never replaced
    state_->jobs->Update(job_id_, JobState::kDone, 1.0,
                         absl::StrFormat("%d keyframes, map version %d", integrated_, version_));
    MaybeFinishLocked();
    return;
  }
  if (step.iterations > 0 || step.keyframes_integrated > 0) {
    WriteLocked(std::move(progress), /*replaceable=*/true);  // progress is advisory
    state_->jobs->Update(job_id_, JobState::kRunning, p.fraction,
                         absl::StrFormat("%d keyframes integrated", integrated_));
  }
  if (!queue_.empty() || !open() || (session_ && session_->has_work())) ScheduleLocked();
}

std::shared_ptr<const MapKeyframes> IntegrateReactor::PublishedKeyframes() const {
  auto keyframes = std::make_shared<MapKeyframes>();
  if (base_keyframes_ != nullptr) *keyframes = *base_keyframes_;
  MapKeyframes integrated = MapKeyframesOf(session_->keyframes());
  keyframes->insert(keyframes->end(), std::make_move_iterator(integrated.begin()),
                    std::make_move_iterator(integrated.end()));
  return keyframes;
}

void IntegrateReactor::OnFailedLocked(const absl::Status& status) {
  queue_.clear();
  if (!job_id_.empty()) {
    state_->jobs->Update(job_id_,
                         status.code() == absl::StatusCode::kCancelled ? JobState::kCancelled
                                                                       : JobState::kFailed,
                         0.0, std::string(status.message()));
  }
}

void IntegrateReactor::OnFinishingLocked() {
  if (lease_) {
    state_->maps->EndMapping(map_name_);
    lease_ = false;
  }
}

std::vector<LogField> IntegrateReactor::LogFields() const {
  return {{"map", map_name_}, {"job", job_id_}, {"keyframes", std::to_string(integrated_)}};
}

}  // namespace plx::server

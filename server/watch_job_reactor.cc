#include "server/watch_job_reactor.h"

#include "server/grpc_status.h"
#include "proto/wire.h"

namespace plx::server {
namespace {

pb::JobStatus::State ToProto(JobState state) {
  switch (state) {
    case JobState::kQueued: return pb::JobStatus::STATE_QUEUED;
    case JobState::kRunning: return pb::JobStatus::STATE_RUNNING;
    case JobState::kDone: return pb::JobStatus::STATE_DONE;
    case JobState::kFailed: return pb::JobStatus::STATE_FAILED;
    case JobState::kCancelled: return pb::JobStatus::STATE_CANCELLED;
  }
  return pb::JobStatus::STATE_UNSPECIFIED;
}

}  // namespace

WatchJobReactor::WatchJobReactor(DaemonState* state, grpc::CallbackServerContext* context,
                                 const pb::WatchJobRequest* request)
    : state_(state) {
  absl::Status status = slot_.Acquire(*state_, context);
  if (!status.ok()) {
    Finish(ToGrpcStatus(status));
    return;
  }
  // Watch calls OnJobChanged once before it returns, which may start the first write.
  absl::StatusOr<int64_t> handle =
      state_->jobs->Watch(request->job_id(), [this](const JobInfo& info) { OnJobChanged(info); });
  std::lock_guard<std::mutex> lock(mutex_);
  if (!handle.ok()) {
    finished_ = true;
    Finish(ToGrpcStatus(handle.status()));
    return;
  }
  handle_ = *handle;
  watching_ = true;
  MaybeFinishLocked();
}

void WatchJobReactor::OnWriteDone(bool ok) {
  std::lock_guard<std::mutex> lock(mutex_);
  write_in_flight_ = false;
  if (!ok) ended_ = true;
  if (next_ && !ended_) {
    current_ = *next_;
    next_.reset();
    write_in_flight_ = true;
    StartWrite(&current_);
  }
  MaybeFinishLocked();
}

void WatchJobReactor::OnCancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  ended_ = true;
  MaybeFinishLocked();
}

// After Unwatch the registry never calls this reactor again; the slot goes back with it
// (StreamSlot's destructor).
void WatchJobReactor::OnDone() {
  if (watching_) state_->jobs->Unwatch(handle_);
  delete this;
}

void WatchJobReactor::OnJobChanged(const JobInfo& info) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_ || ended_) return;
  pb::JobStatus status;
  status.set_job_id(info.id);
  status.set_kind(info.kind);
  status.set_map(info.map);
  status.set_state(ToProto(info.state));
  status.set_progress(info.progress);
  status.set_message(info.message);
  if (info.terminal()) terminal_seen_ = true;
  if (write_in_flight_) {
    next_ = status;
  } else {
    current_ = status;
    write_in_flight_ = true;
    StartWrite(&current_);
  }
}

void WatchJobReactor::MaybeFinishLocked() {
  // A cancelled or broken stream never sends the update still waiting.
  if (ended_) next_.reset();
  if (finished_ || write_in_flight_ || next_) return;
  if (!(terminal_seen_ || ended_)) return;
  finished_ = true;
  Finish(ended_ && !terminal_seen_ ? grpc::Status(grpc::StatusCode::CANCELLED, "cancelled")
                                   : grpc::Status::OK);
}

}  // namespace plx::server

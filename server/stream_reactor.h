// The state machine every bidirectional stream of plenoxd shares (Track, Integrate and Slam):
// admission against the stream limit, reading with optional backpressure, work posted to the
// stream's one device worker, a single-write outbox, and finishing exactly once when the input
// is over, no task is queued or running and every reply has been written. The server-streaming
// calls (Export, WatchJob) write only, so they are grpc::ServerWriteReactors of their own; they
// take their stream slot the same way (server/stream_slot.h).
//
// Phases: kOpen (reading requests) -> kClosing (the client half-closed, or the stream failed or
// was cancelled: no more requests are handled) -> kFinished (Finish called). A subclass handles
// requests and runs its tasks; it calls the *Locked helpers with mutex_ held.
#pragma once

#include <deque>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "server/daemon_state.h"
#include "server/grpc_status.h"
#include "server/log.h"
#include "proto/frame_codec.h"
#include "proto/map_codec.h"
#include "server/stream_slot.h"

namespace plx::server {

template <typename Request, typename Response>
class StreamReactor : public grpc::ServerBidiReactor<Request, Response> {
 public:
  void OnReadDone(bool ok) final {
    std::lock_guard<std::mutex> lock(mutex_);
    reading_ = false;
    if (phase_ != Phase::kOpen) return;
    if (!ok) {
      // A read fails on a cancelled call as on a half-close (OnCancel may come later): a
      // cancelled stream must not end as if its input were complete.
      if (context_->IsCancelled()) {
        FailLocked(CancelledCallStatus(*state_, context_));
        return;
      }
      if (first_) {
        FailLocked(absl::InvalidArgumentError(
            absl::StrCat("empty stream: the first ", request_name_, " must name the map")));
        return;
      }
      phase_ = Phase::kClosing;
      OnInputClosedLocked();
      MaybeFinishLocked();
      return;
    }
    const bool first = first_;
    first_ = false;
    // Every stream works on one map, named by its first message.
    if (first) {
      map_name_ = request_.map();
      if (absl::Status s = CheckMapName(map_name_, "map"); !s.ok()) {
        FailLocked(s);
        return;
      }
    } else if (!request_.map().empty() && request_.map() != map_name_) {
      FailLocked(absl::InvalidArgumentError(absl::StrCat(
          "map: a stream works on one map (\"", map_name_, "\"), got \"", request_.map(), "\"")));
      return;
    }
    // Out of memory while handling one message fails this stream with RESOURCE_EXHAUSTED (an
    // exception must not unwind into gRPC's thread and leave the stream without a status).
    if (absl::Status s = CatchAllocationFailure(absl::StrCat("handling a ", request_name_),
                                                [&] { return HandleRequestLocked(first); });
        !s.ok()) {
      FailLocked(s);
      return;
    }
    if (phase_ == Phase::kOpen && WantsInputLocked()) ReadLocked();
  }

  void OnWriteDone(bool ok) final {
    std::lock_guard<std::mutex> lock(mutex_);
    outbox_.pop_front();
    if (!ok) {
      // The client went away; nothing more can be delivered.
      outbox_.clear();
      write_in_flight_ = false;
      FailLocked(CancelledCallStatus(*state_, context_, "client gone"));
      return;
    }
    if (!outbox_.empty()) {
      this->StartWrite(&outbox_.front().message);
    } else {
      write_in_flight_ = false;
      MaybeFinishLocked();
    }
  }

  void OnCancel() final {
    std::lock_guard<std::mutex> lock(mutex_);
    // Also how a drain's deadline ends the streams still open: the status says which.
    FailLocked(CancelledCallStatus(*state_, context_));
  }

  void OnDone() final {
    std::vector<LogField> fields = {{"method", method_}};
    for (LogField& field : LogFields()) fields.push_back(std::move(field));
    fields.emplace_back("status", std::to_string(final_status_.error_code()));
    if (!final_status_.ok()) fields.emplace_back("message", final_status_.error_message());
    LogEvent(final_status_.ok() ? "info" : "warning", "rpc", fields);
    // After the log line: whoever waits for the stream count to drop sees the stream's line.
    slot_.Release();
    if (worker_ != nullptr) state_->workers->DetachStream(*worker_);
    delete this;
  }

 protected:
  enum class Phase { kOpen, kClosing, kFinished };

  // Admits the stream (drain, auth, stream limit) and starts reading, or finishes it at once.
  // `method` names the RPC in logs, `request_name` the request message in errors.
  StreamReactor(DaemonState* state, grpc::CallbackServerContext* context, const char* method,
                const char* request_name)
      : state_(state), context_(context), method_(method), request_name_(request_name) {
    const absl::Status admitted = slot_.Acquire(*state_, context_);
    if (!admitted.ok()) {
      state_->metrics->rpc_errors++;
      final_status_ = ToGrpcStatus(admitted);
      phase_ = Phase::kFinished;
      this->Finish(final_status_);
      return;
    }
    ReadLocked();  // no reaction runs before the constructor returns
  }
  virtual ~StreamReactor() = default;

  // --- What a stream supplies (mutex_ held) ---
  // Handles request_ (`first`: the stream's first message, whose map name is checked and in
  // map_name_ by then). An error fails the stream.
  virtual absl::Status HandleRequestLocked(bool first) = 0;
  // The client half-closed after at least one message.
  virtual void OnInputClosedLocked() {}
  // The stream failed or was cancelled: drop queued input, mark jobs.
  virtual void OnFailedLocked(const absl::Status& status) { (void)status; }
  // False holds the reads (backpressure); call ResumeReadingLocked when there is room again.
  virtual bool WantsInputLocked() const { return true; }
  // Besides the input being over and the outbox empty: may the stream end on success now?
  virtual bool ReadyToFinishLocked() const { return true; }
  // Called once, just before Finish (release leases).
  virtual void OnFinishingLocked() {}
  // Extra fields of the stream's "rpc" log line.
  virtual std::vector<LogField> LogFields() const { return {}; }

  // --- Helpers (mutex_ held) ---
  // Queues a reply. `replaceable` replies (progress) keep at most one waiting behind the one
  // being written: a newer one replaces it.
  void WriteLocked(Response message, bool replaceable = false) {
    if (write_in_flight_ && replaceable && outbox_.size() > 1 && outbox_.back().replaceable) {
      outbox_.pop_back();
    }
    outbox_.push_back(Outgoing{std::move(message), replaceable});
    if (!write_in_flight_) {
      write_in_flight_ = true;
      this->StartWrite(&outbox_.front().message);
    }
  }

  // Ends the stream with `status` once its task and writes are done (the first failure wins).
  void FailLocked(const absl::Status& status) {
    if (phase_ == Phase::kFinished) return;
    if (final_status_.ok()) final_status_ = ToGrpcStatus(status);
    phase_ = Phase::kClosing;
    OnFailedLocked(status);
    MaybeFinishLocked();
  }

  void MaybeFinishLocked() {
    if (phase_ != Phase::kClosing || busy_ || write_in_flight_ || !outbox_.empty()) return;
    if (final_status_.ok() && !ReadyToFinishLocked()) return;
    phase_ = Phase::kFinished;
    OnFinishingLocked();
    if (!final_status_.ok()) state_->metrics->rpc_errors++;
    this->Finish(final_status_);
  }

  // Takes no more requests, as if the client had half-closed (e.g. the daemon drains).
  void EndInputLocked() {
    if (phase_ != Phase::kOpen) return;
    phase_ = Phase::kClosing;
    OnInputClosedLocked();
    MaybeFinishLocked();
  }

  // Restarts reads held by backpressure.
  void ResumeReadingLocked() {
    if (phase_ == Phase::kOpen && !reading_ && WantsInputLocked()) ReadLocked();
  }

  // Posts one task to the stream's worker (bound at the first post: the stream's tracker or
  // mapper holds that worker's backend) and marks the stream busy until TaskDoneLocked.
  template <typename Task>
  void PostLocked(Priority priority, Task task) {
    busy_ = true;
    if (worker_ == nullptr) worker_ = &state_->workers->AttachStream(priority);
    worker_->Post(priority, std::move(task));
  }
  void TaskDoneLocked() { busy_ = false; }

  // The start of every task: one whose worker stopped (`cancelled`), or whose call was
  // cancelled or has failed, only cleans up and ends the stream. Returns whether to go on.
  bool StartTaskLocked(bool cancelled) {
    // A cancelled call stops before its next step (OnCancel may not have run yet).
    if (!cancelled && !failed() && context_->IsCancelled()) {
      FailLocked(CancelledCallStatus(*state_, context_));
    }
    if (!cancelled && !finished() && !failed()) return true;
    TaskDoneLocked();
    if (cancelled) FailLocked(absl::UnavailableError("plenoxd is shutting down"));
    MaybeFinishLocked();
    return false;
  }

  bool open() const { return phase_ == Phase::kOpen; }
  bool finished() const { return phase_ == Phase::kFinished; }
  bool failed() const { return !final_status_.ok(); }
  bool busy() const { return busy_; }

  DaemonState* const state_;
  grpc::CallbackServerContext* const context_;
  Request request_;
  std::string map_name_;  // set from the first message, before HandleRequestLocked
  std::mutex mutex_;

 private:
  struct Outgoing {
    Response message;
    bool replaceable = false;
  };

  void ReadLocked() {
    reading_ = true;
    this->StartRead(&request_);
  }

  const char* const method_;
  const char* const request_name_;
  StreamSlot slot_;
  Phase phase_ = Phase::kOpen;
  bool first_ = true;
  bool reading_ = false;          // a StartRead is outstanding
  bool busy_ = false;             // a task is queued or running
  bool write_in_flight_ = false;
  grpc::Status final_status_;
  std::deque<Outgoing> outbox_;
  DeviceWorker* worker_ = nullptr;
};

}  // namespace plx::server

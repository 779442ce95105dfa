// The WatchJob stream (server-streaming): a job's status now and after every change, until the
// job ends (then OK) or the call is cancelled (then CANCELLED unless the end was already seen).
// The job registry calls back on the thread that changed the job; updates that arrive while a
// write is in flight are coalesced to the newest, so a slow client never holds a mapping task.
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "server/jobs.h"
#include "server/stream_slot.h"

namespace plx::server {

class WatchJobReactor final : public grpc::ServerWriteReactor<plenoxd::v1::JobStatus> {
 public:
  // Admits the call and starts watching the job (NOT_FOUND for an unknown one), or finishes at
  // once.
  WatchJobReactor(DaemonState* state, grpc::CallbackServerContext* context,
                  const plenoxd::v1::WatchJobRequest* request);

  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

 private:
  void OnJobChanged(const JobInfo& info);
  void MaybeFinishLocked();

  DaemonState* const state_;
  StreamSlot slot_;
  std::mutex mutex_;
  int64_t handle_ = 0;
  bool watching_ = false;  // handle_ is registered: OnDone unwatches it
  // Guarded by mutex_.
  bool write_in_flight_ = false;
  bool terminal_seen_ = false;      // the job's last status is written or waiting in next_
  bool ended_ = false;              // cancelled, or a write failed: nothing more is sent
  bool finished_ = false;           // Finish called
  plenoxd::v1::JobStatus current_;  // being written
  std::optional<plenoxd::v1::JobStatus> next_;  // the newest update behind it
};

}  // namespace plx::server

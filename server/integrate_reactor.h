// The Integrate stream (bidirectional): posed keyframes in, MappingProgress out. The first
// message names a map created with CreateMap; the stream takes that map's writer lease (one
// mapping job per map). Keyframes are decoded on arrival and queued; a mapping task on a device
// worker at background priority adds them, allocates and initialises their bricks, optimises in
// short chunks and publishes new versions of the map to readers. After the client half-closes
// the job spends the rest of its iteration budget, publishes the final version and ends the
// stream with a message that has done = true.
#pragma once

#include <chrono>
#include <deque>
#include <memory>
#include <mutex>

#include <grpcpp/grpcpp.h>

#include "core/mapping/mapping_session.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "server/proto_convert.h"

namespace plx::server {

class IntegrateReactor final : public grpc::ServerBidiReactor<plenoxd::v1::IntegrateRequest,
                                                              plenoxd::v1::MappingProgress> {
 public:
  IntegrateReactor(DaemonState* state, grpc::CallbackServerContext* context);

  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

  // A task longer than this is logged (slow_mapping_task) with where its time went.
  static constexpr double kSlowTaskSeconds = 0.3;
  // Keyframes decoded but not yet integrated before the stream stops reading (backpressure).
  static constexpr size_t kMaxQueuedKeyframes = 8;

 private:
  absl::Status HandleFirstMessage();
  void ScheduleLocked();  // posts one mapping task if none is queued
  void RunTask(Backend* backend, bool cancelled);
  void WriteLocked(plenoxd::v1::MappingProgress progress);
  void FailLocked(const absl::Status& status);
  void MaybeFinishLocked();

  DaemonState* state_;
  grpc::CallbackServerContext* context_;
  plenoxd::v1::IntegrateRequest request_;
  bool holds_slot_ = false;

  std::mutex mutex_;
  bool first_ = true;
  bool lease_ = false;
  bool reading_ = false;        // a StartRead is outstanding
  bool reading_done_ = false;   // the client half-closed (or failed)
  bool busy_ = false;           // a mapping task is queued or running
  DeviceWorker* worker_ = nullptr;  // where every mapping task runs (bound at the first one)
  bool done_sent_ = false;
  bool write_in_flight_ = false;
  bool finished_ = false;
  grpc::Status final_status_;
  std::deque<DecodedFrame> queue_;
  std::deque<plenoxd::v1::MappingProgress> outbox_;
  uint32_t received_ = 0;

  // Owned by the mapping task.
  std::string map_name_;
  std::string job_id_;
  MappingSessionOptions options_;
  std::unique_ptr<MappingSession> session_;
  int integrated_ = 0;
  uint64_t version_ = 0;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace plx::server

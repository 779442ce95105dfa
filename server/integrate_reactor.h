// The Integrate stream (bidirectional): posed keyframes in, MappingProgress out. The first
// message names a map created with CreateMap; the stream takes that map's writer lease (one
// mapping job per map). Keyframes are checked on arrival (CheckFrame) and queued still encoded;
// a mapping task on a device worker at background priority decodes them, adds them, allocates
// and initialises their bricks, optimises in short chunks and publishes new versions of the map
// to readers. After the client half-closes the job spends the rest of its iteration budget,
// publishes the final version and ends the stream with a message that has done = true.
#pragma once

#include <chrono>
#include <deque>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/formats/map_keyframe.h"
#include "core/mapping/mapping_session.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "proto/frame_codec.h"
#include "server/stream_reactor.h"

namespace plx::server {

class IntegrateReactor final
    : public StreamReactor<plenoxd::v1::IntegrateRequest, plenoxd::v1::MappingProgress> {
 public:
  IntegrateReactor(DaemonState* state, grpc::CallbackServerContext* context);

  // A task longer than this is logged (slow_mapping_task) with where its time went.
  static constexpr double kSlowTaskSeconds = 0.3;
  // Keyframes received but not yet integrated before the stream stops reading (backpressure).
  static constexpr size_t kMaxQueuedKeyframes = 8;

 private:
  absl::Status HandleRequestLocked(bool first) override;
  void OnInputClosedLocked() override;
  void OnFailedLocked(const absl::Status& status) override;
  bool WantsInputLocked() const override { return queue_.size() < kMaxQueuedKeyframes; }
  bool ReadyToFinishLocked() const override { return !lease_ || done_sent_; }
  void OnFinishingLocked() override;
  std::vector<LogField> LogFields() const override;

  absl::Status HandleFirstMessage();
  void ScheduleLocked();  // posts one mapping task if none is queued
  void RunTask(Backend* backend, bool cancelled);
  // Every keyframe of the version being published, as its file keeps them: the map's before
  // the stream, then the session's (mapping task).
  std::shared_ptr<const MapKeyframes> PublishedKeyframes() const;

  // Guarded by mutex_.
  bool lease_ = false;
  bool done_sent_ = false;
  std::deque<CheckedFrame> queue_;  // still encoded
  uint32_t received_ = 0;

  // Owned by the mapping task.
  std::string job_id_;
  MappingSessionOptions options_;
  std::unique_ptr<MappingSession> session_;
  std::shared_ptr<const MapKeyframes> base_keyframes_;  // the map's when the session started
  int integrated_ = 0;
  uint64_t version_ = 0;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace plx::server

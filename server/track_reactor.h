// The Track stream (bidirectional): frames in, one PoseEstimate out per frame served. Frames are
// decoded on arrival; tracking runs on a device worker at interactive priority. While a frame
// is being tracked, newer frames replace the waiting one (latest wins) and the next estimate
// reports how many were dropped. The tracker follows the newest published version of the map.
#pragma once

#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "core/tracking/tracker.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "server/proto_convert.h"

namespace plx::server {

class TrackReactor final
    : public grpc::ServerBidiReactor<plenoxd::v1::TrackRequest, plenoxd::v1::PoseEstimate> {
 public:
  TrackReactor(DaemonState* state, grpc::CallbackServerContext* context);

  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

 private:
  struct Pending {
    DecodedFrame frame;
    std::chrono::steady_clock::time_point received;
    std::optional<SE3> initial_pose;  // the stream's start: reported as-is, resets the tracker
  };

  absl::Status HandleFirstMessage();
  void Submit();  // posts the tracking task; mutex_ held
  void RunTask(Backend* backend, bool cancelled);
  void Write(plenoxd::v1::PoseEstimate estimate);  // mutex_ held
  void FailLocked(const absl::Status& status);     // mutex_ held
  void MaybeFinishLocked();                        // mutex_ held

  DaemonState* state_;
  grpc::CallbackServerContext* context_;
  plenoxd::v1::TrackRequest request_;
  bool holds_slot_ = false;

  std::mutex mutex_;
  bool first_ = true;
  bool reading_done_ = false;
  bool busy_ = false;             // a task is queued or running
  bool write_in_flight_ = false;
  bool finished_ = false;
  grpc::Status final_status_;
  std::optional<Pending> pending_;
  // TrackRequest.initial_pose from a first message without a frame, waiting for the first frame.
  std::optional<SE3> initial_pose_;
  uint32_t dropped_ = 0;
  std::deque<plenoxd::v1::PoseEstimate> outbox_;

  // Owned by the task (one at a time).
  std::string map_name_;
  TrackerOptions options_;
  MapVersion map_;
  std::unique_ptr<Tracker> tracker_;
  // The worker every task of this stream runs on (bound at the first Submit, mutex_ held).
  DeviceWorker* worker_ = nullptr;
  bool tracker_started_ = false;
};

}  // namespace plx::server

// The Track stream (bidirectional): frames in, one PoseEstimate out per frame served. Frames are
// checked on arrival (CheckFrame: sizes, headers, pose) and decoded by the tracking task, which
// runs on a device worker at interactive priority. While a frame is being tracked, newer frames
// replace the waiting one (latest wins, so a dropped frame is never decoded) and the next
// estimate reports how many were dropped. The tracker follows the newest published version of
// the map.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <utility>
#include <vector>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "core/tracking/tracker.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "proto/frame_codec.h"
#include "server/stream_reactor.h"

namespace plx::server {

class TrackReactor final
    : public StreamReactor<plenoxd::v1::TrackRequest, plenoxd::v1::PoseEstimate> {
 public:
  TrackReactor(DaemonState* state, grpc::CallbackServerContext* context);

 private:
  struct Pending {
    CheckedFrame frame;  // still encoded
    std::chrono::steady_clock::time_point received;
    std::optional<SE3> initial_pose;  // the stream's start: reported as-is, resets the tracker
  };

  absl::Status HandleRequestLocked(bool first) override;
  void OnFailedLocked(const absl::Status& status) override;
  std::vector<LogField> LogFields() const override;

  absl::Status HandleFirstMessage();
  void Submit();  // posts the tracking task; mutex_ held
  void RunTask(Backend* backend, bool cancelled);

  std::optional<Pending> pending_;  // guarded by mutex_
  // TrackRequest.initial_pose from a first message without a frame, waiting for the first frame.
  std::optional<SE3> initial_pose_;
  uint32_t dropped_ = 0;

  // Owned by the task (one at a time).
  TrackerOptions options_;
  MapVersion map_;
  std::unique_ptr<Tracker> tracker_;
  bool tracker_started_ = false;
};

}  // namespace plx::server

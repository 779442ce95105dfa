// The Slam stream (bidirectional): unposed frames in, one SlamUpdate out per processed frame,
// while the map's SLAM job (server/slam_job.h) grows the map from the keyframes this and the
// other Slam streams on the map hand it. The stream is one camera: a SlamTracker
// (core/slam/slam_tracker.h) run by tracking tasks at interactive priority on the stream's
// device worker; the mapping runs as the job's background tasks.
//
// Frames are checked on arrival (CheckFrame) and decoded by the tracking task. Realtime streams
// keep only the newest waiting frame (latest wins); others queue a few and stop reading
// (backpressure). After a keyframe the next frame waits until the job has integrated it (in
// lock-step mode: until the job has spent its iterations too), so the tracker never outruns
// the map. After the client half-closes and every frame is processed, the stream leaves the
// job and ends with a `done` update; the last stream on a map sends it once the job has
// published its final version.
#pragma once

#include <chrono>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/slam/slam_tracker.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "proto/frame_codec.h"
#include "server/slam_job.h"
#include "server/stream_reactor.h"

namespace plx::server {

class SlamReactor final : public StreamReactor<plenoxd::v1::SlamRequest, plenoxd::v1::SlamUpdate> {
 public:
  SlamReactor(DaemonState* state, grpc::CallbackServerContext* context);
  ~SlamReactor() override;

  // Frames received but not yet tracked before a non-realtime stream stops reading.
  static constexpr size_t kMaxQueuedFrames = 8;

 private:
  struct Pending {
    CheckedFrame frame;  // still encoded
    uint32_t index = 0;  // 0-based position in the stream (frame[index] in errors)
    std::chrono::steady_clock::time_point received;
  };

  absl::Status HandleRequestLocked(bool first) override;
  void OnInputClosedLocked() override;
  void OnFailedLocked(const absl::Status& status) override;
  bool WantsInputLocked() const override {
    return realtime_ || queue_.size() < kMaxQueuedFrames;
  }
  bool ReadyToFinishLocked() const override { return done_sent_; }
  std::vector<LogField> LogFields() const override;

  absl::Status HandleFirstMessage();
  // Posts the tracking task when a frame waits, none is running and the job lets the stream
  // go on; after the input is over and the queue is empty, leaves the job and sends `done`.
  void AdvanceLocked();
  bool JobAllowsNextFrameLocked();
  void OnJobChanged();  // the job's listener
  void RunTask(Backend* backend, bool cancelled);
  void LeaveJobLocked();

  // Guarded by mutex_.
  std::deque<Pending> queue_;
  uint32_t dropped_ = 0;
  bool realtime_ = false;
  int max_pending_keyframes_ = 0;  // this stream's SlamGateOptions (lock-step is the job's)
  bool wait_for_job_ = false;  // the last frame became a keyframe, or the map has no version:
                               // the next waits for SlamJob::MayCameraProceed
  int segment_ = 0;            // the camera's map segment (SlamCoordinator::Accept)
  bool needs_version_ = true;  // the camera cannot go on without a version (the tracker's)
  bool left_job_ = false;
  bool done_sent_ = false;
  std::shared_ptr<SlamJob> job_;
  std::shared_ptr<SlamJobListener> listener_;
  int camera_ = -1;  // this stream's camera in the job's TrajectoryRecord
  uint32_t received_ = 0;   // frames received (dropped ones too)
  uint32_t processed_ = 0;  // updates sent
  int keyframes_ = 0;
  std::optional<SlamState> last_state_;  // logged when it changes
  // The last update's pose, its segment and the corrections it followed: where the done
  // message's corrections_after start.
  SE3 last_pose_;
  int last_segment_ = 0;
  int last_generation_ = 0;

  // Owned by the tracking task (one at a time).
  SlamTrackerOptions tracker_options_;
  std::unique_ptr<SlamTracker> tracker_;
};

}  // namespace plx::server

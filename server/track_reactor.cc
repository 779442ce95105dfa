#include "server/track_reactor.h"

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "proto/track_codec.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {

TrackReactor::TrackReactor(DaemonState* state, grpc::CallbackServerContext* context)
    : StreamReactor(state, context, "Track", "TrackRequest") {}

absl::Status TrackReactor::HandleFirstMessage() {
  absl::StatusOr<MapVersion> map = state_->maps->Latest(map_name_);
  if (!map.ok()) return map.status();
  map_ = *map;
  PLX_ASSIGN_OR_RETURN(options_, TrackerOptionsFromProto(request_.options(), "options"));
  return absl::OkStatus();
}

absl::Status TrackReactor::HandleRequestLocked(bool first) {
  if (first) {
    PLX_RETURN_IF_ERROR(HandleFirstMessage());
    if (request_.has_initial_pose()) {
      PLX_ASSIGN_OR_RETURN(const SE3 pose, PoseFromProto(request_.initial_pose(), "initial_pose"));
      PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(pose, "initial_pose"));
      // Held until a frame arrives: the first message may name the map and the start only.
      initial_pose_ = pose;
    }
  }
  if (request_.has_frame()) {
    PLX_ASSIGN_OR_RETURN(CheckedFrame frame,
                         CheckFrame(std::move(*request_.mutable_frame()), "frame", false,
                                    state_->config.max_frame_pixels));
    if (frame.client_pose) {
      PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(*frame.client_pose, "frame.pose"));
    }
    // Latest wins: a frame still waiting is stale now, except the stream's starting frame,
    // which defines its origin (then the new frame is the one dropped).
    if (pending_) {
      ++dropped_;
      state_->metrics->frames_dropped++;
    }
    if (!(pending_ && pending_->initial_pose)) {
      pending_ = Pending{std::move(frame), std::chrono::steady_clock::now(), initial_pose_};
      initial_pose_.reset();
      if (!busy()) Submit();
    }
  }
  return absl::OkStatus();
}

void TrackReactor::Submit() {
  PostLocked(Priority::kInteractive,
             [this](Backend* backend, bool cancelled) { RunTask(backend, cancelled); });
}

void TrackReactor::RunTask(Backend* backend, bool cancelled) {
  std::optional<Pending> work;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!StartTaskLocked(cancelled)) return;
    work = std::move(pending_);
    pending_.reset();
  }
  pb::PoseEstimate estimate;
  bool client_error = false;  // the frame's data was bad: no error log, the stream just ends
  std::optional<DecodedFrame> decoded;
  // The backend's errors (memory, device) and out of memory anywhere in the step end this
  // stream with a status; they must not escape into the worker thread.
  const absl::Status failure = CatchAllocationFailure("tracking a frame", [&]() -> absl::Status {
    if (!work) return absl::OkStatus();
    absl::StatusOr<DecodedFrame> d = DecodeCheckedFrame(std::move(work->frame));
    if (!d.ok()) {
      client_error = d.status().code() == absl::StatusCode::kInvalidArgument;
      return d.status();
    }
    decoded = *std::move(d);
    // Follow the mapping job: newer published versions replace the one being tracked against.
    absl::StatusOr<MapVersion> latest = state_->maps->Latest(map_name_);
    if (latest.ok() && latest->version != map_.version) {
      map_ = *latest;
      if (tracker_) tracker_->set_map(map_.map.get());
    }
    if (!tracker_) tracker_ = std::make_unique<Tracker>(map_.map.get(), backend, options_);
    const RgbdFrame& frame = decoded->frame;
    TrackingResult result;
    if (work->initial_pose || !tracker_started_) {
      // The stream's first frame: start from the given pose (or the frame's prior, or the
      // identity) and report it, as the in-process tracker does for frame 0.
      const SE3 start = work->initial_pose.value_or(decoded->client_pose.value_or(SE3()));
      tracker_->Reset(start, frame.timestamp);
      tracker_started_ = true;
      result.pose = start;
      result.state = TrackingState::kOk;
      result.reason =
          work->initial_pose ? "initial pose" : "initial pose (frame prior or identity)";
    } else {
      absl::StatusOr<TrackingResult> tracked =
          tracker_->Track(frame, decoded->calibration.pinhole, decoded->client_pose);
      if (!tracked.ok()) return tracked.status();  // the backend's (memory, device)
      result = *std::move(tracked);
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - work->received).count();
    estimate = PoseEstimateToProto(result, frame.timestamp, map_.version, 1000.0 * seconds);
    state_->metrics->frames_tracked++;
    if (result.state == TrackingState::kLost) state_->metrics->frames_lost++;
    state_->metrics->ObserveTrackLatency(seconds);
    return absl::OkStatus();
  });
  std::lock_guard<std::mutex> lock(mutex_);
  if (!failure.ok()) {
    TaskDoneLocked();
    if (!client_error) {
      LogEvent("error", "track_failed", {{"map", map_name_}, {"error", failure.ToString()}});
    }
    FailLocked(failure);
    return;
  }
  if (decoded && !finished()) {
    estimate.set_dropped(dropped_);
    dropped_ = 0;
    WriteLocked(std::move(estimate));
  }
  TaskDoneLocked();
  if (pending_ && !finished()) {
    Submit();  // one task per frame keeps the worker fair between streams
  } else {
    MaybeFinishLocked();
  }
}

void TrackReactor::OnFailedLocked(const absl::Status&) { pending_.reset(); }

std::vector<LogField> TrackReactor::LogFields() const {
  return {{"map", map_name_}};
}

}  // namespace plx::server

#include "server/track_reactor.h"

#include "absl/strings/str_cat.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {
namespace {

pb::TrackingState ToProto(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return pb::TRACKING_STATE_OK;
    case TrackingState::kDegraded: return pb::TRACKING_STATE_DEGRADED;
    case TrackingState::kLost: return pb::TRACKING_STATE_LOST;
  }
  return pb::TRACKING_STATE_UNSPECIFIED;
}

}  // namespace

TrackReactor::TrackReactor(DaemonState* state, grpc::CallbackServerContext* context)
    : state_(state), context_(context) {
  const absl::Status admitted = AcquireStreamSlot(*state_, context_);
  if (!admitted.ok()) {
    state_->metrics->rpc_errors++;
    final_status_ = ToGrpcStatus(admitted);
    finished_ = true;
    Finish(final_status_);
    return;
  }
  holds_slot_ = true;
  StartRead(&request_);
}

absl::Status TrackReactor::HandleFirstMessage() {
  map_name_ = request_.map();
  if (absl::Status s = CheckMapName(map_name_, "map"); !s.ok()) return s;
  absl::StatusOr<MapVersion> map = state_->maps->Latest(map_name_);
  if (!map.ok()) return map.status();
  map_ = *map;
  const pb::TrackOptions& o = request_.options();
  options_ = TrackerOptionsForMode(o.mode() == pb::TrackOptions::MODE_ADAM
                                      ? TrackingMode::kAdam
                                      : TrackingMode::kGaussNewton);
  if (o.rays() > 0) options_.rays = static_cast<int>(o.rays());
  if (o.iterations() > 0) options_.iterations = static_cast<int>(o.iterations());
  if (absl::Status s = Tracker::ValidateOptions(options_); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", s.message()));
  }
  return absl::OkStatus();
}

void TrackReactor::OnReadDone(bool ok) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!ok) {
    if (first_ && !finished_ && final_status_.ok()) {
      FailLocked(absl::InvalidArgumentError("empty stream: the first TrackRequest must name the map"));
      return;
    }
    reading_done_ = true;
    MaybeFinishLocked();
    return;
  }
  if (finished_) return;
  if (first_) {
    first_ = false;
    if (absl::Status s = HandleFirstMessage(); !s.ok()) {
      FailLocked(s);
      return;
    }
    if (request_.has_initial_pose()) {
      absl::StatusOr<SE3> pose = PoseFromProto(request_.initial_pose(), "initial_pose");
      if (!pose.ok()) {
        FailLocked(pose.status());
        return;
      }
      // Held until a frame arrives: the first message may name the map and the start only.
      initial_pose_ = *pose;
    }
  }
  if (request_.has_frame()) {
    absl::StatusOr<DecodedFrame> frame = FrameFromProto(request_.frame(), "frame", false);
    if (!frame.ok()) {
      FailLocked(frame.status());
      return;
    }
    // Latest wins: a frame still waiting is stale now, except the stream's starting frame,
    // which defines its origin (then the new frame is the one dropped).
    if (pending_) {
      ++dropped_;
      state_->metrics->frames_dropped++;
    }
    if (!(pending_ && pending_->initial_pose)) {
      pending_ = Pending{std::move(*frame), std::chrono::steady_clock::now(), initial_pose_};
      initial_pose_.reset();
      if (!busy_) Submit();
    }
  }
  StartRead(&request_);
}

void TrackReactor::Submit() {
  busy_ = true;
  // The stream stays on the worker of its first frame: its Tracker holds that worker's backend.
  if (worker_ == nullptr) worker_ = &state_->workers->AttachStream();
  worker_->Post(Priority::kInteractive,
                               [this](Backend* backend, bool cancelled) { RunTask(backend, cancelled); });
}

void TrackReactor::RunTask(Backend* backend, bool cancelled) {
  std::optional<Pending> work;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (cancelled || finished_) {
      busy_ = false;
      if (cancelled) FailLocked(absl::UnavailableError("plenoxd is shutting down"));
      MaybeFinishLocked();
      return;
    }
    work = std::move(pending_);
    pending_.reset();
  }
  pb::PoseEstimate estimate;
  absl::Status failure;
  if (work) {
    // Follow the mapping job: newer published versions replace the one being tracked against.
    absl::StatusOr<MapVersion> latest = state_->maps->Latest(map_name_);
    if (latest.ok() && latest->version != map_.version) {
      map_ = *latest;
      if (tracker_) tracker_->set_map(map_.map.get());
    }
    if (!tracker_) tracker_ = std::make_unique<Tracker>(map_.map.get(), backend, options_);
    const RgbdFrame& frame = work->frame.frame;
    TrackingResult result;
    if (work->initial_pose || !tracker_started_) {
      // The stream's first frame: start from the given pose (or the frame's prior, or the
      // identity) and report it, as the in-process tracker does for frame 0.
      const SE3 start = work->initial_pose.value_or(work->frame.client_pose.value_or(SE3()));
      tracker_->Reset(start, frame.timestamp);
      tracker_started_ = true;
      result.pose = start;
      result.state = TrackingState::kOk;
      result.reason = work->initial_pose ? "initial pose" : "initial pose (frame prior or identity)";
    } else {
      absl::StatusOr<TrackingResult> tracked =
          tracker_->Track(frame, work->frame.calibration.pinhole, work->frame.client_pose);
      if (tracked.ok()) {
        result = *std::move(tracked);
      } else {
        failure = tracked.status();  // the backend's (memory, device): this stream ends
      }
    }
    estimate.set_timestamp(frame.timestamp);
    PoseToProto(result.pose, estimate.mutable_pose());
    estimate.set_state(ToProto(result.state));
    estimate.set_reason(result.reason);
    estimate.set_valid_rays(static_cast<uint32_t>(result.valid_rays));
    estimate.set_map_version(map_.version);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - work->received).count();
    estimate.set_latency_ms(1000.0 * seconds);
    state_->metrics->frames_tracked++;
    if (result.state == TrackingState::kLost) state_->metrics->frames_lost++;
    state_->metrics->ObserveTrackLatency(seconds);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!failure.ok()) {
    busy_ = false;
    LogEvent("error", "track_failed", {{"map", map_name_}, {"error", failure.ToString()}});
    FailLocked(failure);
    return;
  }
  if (work && !finished_) {
    estimate.set_dropped(dropped_);
    dropped_ = 0;
    Write(std::move(estimate));
  }
  busy_ = false;
  if (pending_ && !finished_) {
    Submit();  // one task per frame keeps the worker fair between streams
  } else {
    MaybeFinishLocked();
  }
}

void TrackReactor::Write(pb::PoseEstimate estimate) {
  outbox_.push_back(std::move(estimate));
  if (!write_in_flight_) {
    write_in_flight_ = true;
    StartWrite(&outbox_.front());
  }
}

void TrackReactor::OnWriteDone(bool ok) {
  std::lock_guard<std::mutex> lock(mutex_);
  outbox_.pop_front();
  if (!ok) {
    // The client went away; nothing more can be delivered.
    outbox_.clear();
    write_in_flight_ = false;
    reading_done_ = true;
    pending_.reset();
    if (final_status_.ok()) final_status_ = grpc::Status(grpc::StatusCode::CANCELLED, "client gone");
    MaybeFinishLocked();
    return;
  }
  if (!outbox_.empty()) {
    StartWrite(&outbox_.front());
  } else {
    write_in_flight_ = false;
    MaybeFinishLocked();
  }
}

void TrackReactor::OnCancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  pending_.reset();
  reading_done_ = true;
  if (final_status_.ok()) final_status_ = grpc::Status(grpc::StatusCode::CANCELLED, "cancelled");
  MaybeFinishLocked();
}

void TrackReactor::FailLocked(const absl::Status& status) {
  if (final_status_.ok()) final_status_ = ToGrpcStatus(status);
  pending_.reset();
  reading_done_ = true;
  MaybeFinishLocked();
}

void TrackReactor::MaybeFinishLocked() {
  if (finished_ || !reading_done_ || busy_ || write_in_flight_ || !outbox_.empty()) return;
  finished_ = true;
  if (!final_status_.ok()) state_->metrics->rpc_errors++;
  Finish(final_status_);
}

void TrackReactor::OnDone() {
  if (holds_slot_) ReleaseStreamSlot(*state_);
  if (worker_ != nullptr) state_->workers->DetachStream(*worker_);
  LogEvent("info", "rpc", {{"method", "Track"}, {"map", map_name_},
                           {"status", std::to_string(final_status_.error_code())}});
  delete this;
}

}  // namespace plx::server

#include "server/integrate_reactor.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

IntegrateReactor::IntegrateReactor(DaemonState* state, grpc::CallbackServerContext* context)
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
  reading_ = true;
  StartRead(&request_);
}

absl::Status IntegrateReactor::HandleFirstMessage() {
  map_name_ = request_.map();
  if (absl::Status s = CheckMapName(map_name_, "map"); !s.ok()) return s;
  absl::StatusOr<MapStatus> info = state_->maps->Info(map_name_);
  if (!info.ok()) return info.status();
  const pb::IntegrateOptions& o = request_.options();
  options_ = MapperOptionsForVoxelSize(info->voxel_size);
  if (o.rays_per_iteration() > 0) options_.batch_size = static_cast<int>(o.rays_per_iteration());
  if (o.iterations_per_keyframe() > 0) {
    iterations_per_keyframe_ = static_cast<int>(o.iterations_per_keyframe());
  }
  if (o.max_depth() > 0) {
    options_.allocation.max_depth = o.max_depth();
    options_.fusion.max_depth = o.max_depth();
  }
  options_.max_iterations = 1;  // raised as keyframes arrive
  if (absl::Status s = Mapper::ValidateOptions(options_); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", s.message()));
  }
  if (iterations_per_keyframe_ > 100000) {
    return absl::InvalidArgumentError("options.iterations_per_keyframe: at most 100000");
  }
  if (absl::Status s = state_->maps->BeginMapping(map_name_); !s.ok()) return s;
  lease_ = true;
  job_id_ = state_->jobs->Create("integrate", map_name_);
  state_->jobs->Update(job_id_, JobState::kRunning, 0.0, "waiting for keyframes");
  start_ = last_publish_ = std::chrono::steady_clock::now();
  LogEvent("info", "mapping_started", {{"map", map_name_}, {"job", job_id_}});
  return absl::OkStatus();
}

void IntegrateReactor::OnReadDone(bool ok) {
  std::lock_guard<std::mutex> lock(mutex_);
  reading_ = false;
  if (!ok) {
    if (first_ && !finished_) {
      FailLocked(absl::InvalidArgumentError(
          "empty stream: the first IntegrateRequest must name the map"));
      return;
    }
    reading_done_ = true;
    if (lease_ && !finished_) ScheduleLocked();  // spend the rest of the budget, then finish
    MaybeFinishLocked();
    return;
  }
  if (finished_ || !final_status_.ok()) return;
  if (first_) {
    first_ = false;
    if (absl::Status s = HandleFirstMessage(); !s.ok()) {
      FailLocked(s);
      return;
    }
  } else if (!request_.map().empty() && request_.map() != map_name_) {
    FailLocked(absl::InvalidArgumentError(
        absl::StrCat("map: a stream maps one map (\"", map_name_, "\"), got \"", request_.map(), "\"")));
    return;
  }
  if (request_.has_frame()) {
    absl::StatusOr<DecodedFrame> frame =
        FrameFromProto(request_.frame(), absl::StrCat("frame[", received_, "]"), true);
    if (!frame.ok()) {
      FailLocked(frame.status());
      return;
    }
    queue_.push_back(std::move(*frame));
    ++received_;
    ScheduleLocked();
  }
  // Backpressure: stop reading while the mapping task is behind; it resumes the reads.
  if (queue_.size() < kMaxQueuedKeyframes) {
    reading_ = true;
    StartRead(&request_);
  }
}

void IntegrateReactor::ScheduleLocked() {
  if (busy_) return;
  busy_ = true;
  // The stream stays on one worker: its Mapper holds that worker's backend.
  if (worker_ == nullptr) worker_ = &state_->workers->AttachStream();
  worker_->Post(Priority::kBackground,
                               [this](Backend* backend, bool cancelled) { RunTask(backend, cancelled); });
}

void IntegrateReactor::RunTask(Backend* backend, bool cancelled) {
  std::deque<DecodedFrame> frames;
  bool input_closed = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (cancelled || finished_ || !final_status_.ok()) {
      busy_ = false;
      if (cancelled) FailLocked(absl::UnavailableError("plenoxd is shutting down"));
      MaybeFinishLocked();
      return;
    }
    // One keyframe per task: integrating one (brick allocation, depth fusion) is the longest
    // step a task cannot split, and a tracking frame may be queued behind it.
    if (!queue_.empty()) {
      frames.push_back(std::move(queue_.front()));
      queue_.pop_front();
    }
    input_closed = reading_done_ && queue_.empty();
    if (!reading_ && !reading_done_) {
      reading_ = true;
      StartRead(&request_);
    }
  }
  const auto task_start = std::chrono::steady_clock::now();
  double integrate_s = 0.0, optimize_s = 0.0, snapshot_s = 0.0;
  absl::Status status = absl::OkStatus();
  if (!mapper_ && !frames.empty()) {
    absl::StatusOr<MapVersion> latest = state_->maps->Latest(map_name_);
    if (latest.ok()) {
      // The job continues the published map on its own copy; readers keep the published one.
      mapper_ = std::make_unique<Mapper>(
          options_, backend, std::make_unique<PlenoxelMap>(latest->map->ShareCopy()));
    } else {
      status = latest.status();
    }
  }
  for (DecodedFrame& f : frames) {
    if (!status.ok()) break;
    const SE3 pose = *f.frame.world_T_camera;
    status = mapper_->AddKeyframe(std::move(f.frame), pose, f.calibration.pinhole);
    if (status.ok()) {
      ++integrated_;
      ++unpublished_keyframes_;
      state_->metrics->keyframes_integrated++;
    }
  }
  if (status.ok() && mapper_ && !frames.empty()) {
    const auto integrate_start = std::chrono::steady_clock::now();
    status = mapper_->AllocateAndInitialize();
    integrate_s = SecondsSince(integrate_start);
    mapper_->set_max_iterations(iterations_per_keyframe_ * mapper_->training_set().num_frames());
  }
  bool optimised = false;
  if (status.ok() && mapper_ && !mapper_->budget_spent() && mapper_->training_set().num_rays() > 0) {
    const auto optimize_start = std::chrono::steady_clock::now();
    absl::StatusOr<MappingSummary> summary = mapper_->Optimize(
        [&](const MappingProgress&) { return true; }, kChunkIterations, kChunkSeconds);
    optimize_s = SecondsSince(optimize_start);
    if (summary.ok()) {
      last_ = summary->last;
      optimised = true;
    } else {
      status = summary.status();
    }
  }
  const bool finishing = input_closed && (!mapper_ || mapper_->budget_spent() ||
                                          mapper_->training_set().num_rays() == 0);
  // Publishing copies the whole map on this worker, so large maps publish less often: the copy
  // takes at most about a tenth of the worker's time.
  const double publish_gap = std::max(1.0, 10.0 * last_snapshot_s_);
  if (status.ok() && mapper_ &&
      (finishing || (unpublished_keyframes_ > 0 && SecondsSince(last_publish_) > publish_gap) ||
       SecondsSince(last_publish_) > 3.0 * publish_gap)) {
    const auto snapshot_start = std::chrono::steady_clock::now();
    absl::StatusOr<std::shared_ptr<const PlenoxelMap>> snapshot = mapper_->Publish();
    last_snapshot_s_ = snapshot_s = SecondsSince(snapshot_start);
    absl::StatusOr<uint64_t> version =
        snapshot.ok() ? state_->maps->Publish(map_name_, *std::move(snapshot), unpublished_keyframes_)
                      : snapshot.status();
    if (version.ok()) {
      version_ = *version;
      unpublished_keyframes_ = 0;
      last_publish_ = std::chrono::steady_clock::now();
    } else {
      status = version.status();
    }
  }

  // Every tracking frame on this worker waits for a task in progress: say when one was long.
  if (const double task_s = SecondsSince(task_start); task_s > kSlowTaskSeconds) {
    LogEvent("warning", "slow_mapping_task",
             {{"map", map_name_}, {"job", job_id_}, {"seconds", absl::StrFormat("%.3f", task_s)},
              {"integrate_s", absl::StrFormat("%.3f", integrate_s)},
              {"optimize_s", absl::StrFormat("%.3f", optimize_s)},
              {"snapshot_s", absl::StrFormat("%.3f", snapshot_s)}});
  }
  pb::MappingProgress progress;
  progress.set_job_id(job_id_);
  progress.set_keyframes_integrated(static_cast<uint32_t>(integrated_));
  progress.set_iterations(mapper_ ? static_cast<uint32_t>(mapper_->iterations_done()) : 0);
  progress.set_train_psnr(last_.psnr);
  progress.set_train_depth_l1_m(last_.depth_l1_m);
  progress.set_map_version(version_);
  progress.set_elapsed_s(SecondsSince(start_));
  const double fraction =
      mapper_ && iterations_per_keyframe_ > 0 && integrated_ > 0
          ? std::min(1.0, double(mapper_->iterations_done()) / (iterations_per_keyframe_ * integrated_))
          : 0.0;

  std::lock_guard<std::mutex> lock(mutex_);
  busy_ = false;
  progress.set_keyframes_received(received_);
  if (!status.ok()) {
    FailLocked(status);
    return;
  }
  if (finished_) return;
  if (finishing && queue_.empty()) {
    progress.set_done(true);
    done_sent_ = true;
    WriteLocked(std::move(progress));
    state_->jobs->Update(job_id_, JobState::kDone, 1.0,
                         absl::StrFormat("%d keyframes, map version %d", integrated_, version_));
    MaybeFinishLocked();
    return;
  }
  if (optimised || !frames.empty()) {
    WriteLocked(std::move(progress));
    state_->jobs->Update(job_id_, JobState::kRunning, fraction,
                         absl::StrFormat("%d keyframes integrated", integrated_));
  }
  const bool more = !queue_.empty() || reading_done_ ||
                    (mapper_ && !mapper_->budget_spent() && mapper_->training_set().num_rays() > 0);
  if (more) ScheduleLocked();
}

void IntegrateReactor::WriteLocked(pb::MappingProgress progress) {
  // Progress is advisory: keep at most one waiting message behind the one being written,
  // except the final one.
  if (write_in_flight_ && outbox_.size() > 1 && !outbox_.back().done()) outbox_.pop_back();
  outbox_.push_back(std::move(progress));
  if (!write_in_flight_) {
    write_in_flight_ = true;
    StartWrite(&outbox_.front());
  }
}

void IntegrateReactor::OnWriteDone(bool ok) {
  std::lock_guard<std::mutex> lock(mutex_);
  outbox_.pop_front();
  if (!ok) {
    outbox_.clear();
    write_in_flight_ = false;
    FailLocked(absl::CancelledError("client gone"));
    return;
  }
  if (!outbox_.empty()) {
    StartWrite(&outbox_.front());
  } else {
    write_in_flight_ = false;
    MaybeFinishLocked();
  }
}

void IntegrateReactor::OnCancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  FailLocked(absl::CancelledError("cancelled by the client"));
}

void IntegrateReactor::FailLocked(const absl::Status& status) {
  if (final_status_.ok()) final_status_ = ToGrpcStatus(status);
  queue_.clear();
  reading_done_ = true;
  if (!job_id_.empty()) {
    state_->jobs->Update(job_id_,
                         status.code() == absl::StatusCode::kCancelled ? JobState::kCancelled
                                                                       : JobState::kFailed,
                         0.0, std::string(status.message()));
  }
  MaybeFinishLocked();
}

void IntegrateReactor::MaybeFinishLocked() {
  if (finished_ || busy_ || write_in_flight_ || !outbox_.empty()) return;
  if (final_status_.ok() && (!reading_done_ || (lease_ && !done_sent_))) return;
  finished_ = true;
  if (lease_) {
    state_->maps->EndMapping(map_name_);
    lease_ = false;
  }
  if (!final_status_.ok()) state_->metrics->rpc_errors++;
  Finish(final_status_);
}

void IntegrateReactor::OnDone() {
  if (holds_slot_) ReleaseStreamSlot(*state_);
  if (worker_ != nullptr) state_->workers->DetachStream(*worker_);
  LogEvent("info", "rpc", {{"method", "Integrate"}, {"map", map_name_}, {"job", job_id_},
                           {"keyframes", std::to_string(integrated_)},
                           {"status", std::to_string(final_status_.error_code())}});
  delete this;
}

}  // namespace plx::server

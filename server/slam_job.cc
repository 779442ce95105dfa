#include "server/slam_job.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "server/log.h"

namespace plx::server {

void SlamJobListener::Notify() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (notify_) notify_();
}

void SlamJobListener::Reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  notify_ = nullptr;
}

SlamJob::SlamJob(DaemonState* state, std::string map, std::string job_id,
                 SlamMapperOptions options, bool deterministic,
                 std::shared_ptr<TrajectoryRecord> trajectory)
    : state_(state),
      map_(std::move(map)),
      job_id_(std::move(job_id)),
      options_(std::move(options)),
      deterministic_(deterministic),
      trajectory_(std::move(trajectory)) {
  status_.job_id = job_id_;
  if (absl::StatusOr<MapVersion> latest = state_->maps->Latest(map_); latest.ok()) {
    status_.map_version = latest->version;
    if (latest->map != nullptr && latest->map->grid.num_bricks() > 0) base_ = latest->map;
  }
}

SlamJob::~SlamJob() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (worker_ != nullptr) state_->workers->DetachStream(*worker_);
}

absl::Status SlamJob::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                  const PinholeIntrinsics& k) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (status_.finished) {
      return absl::FailedPreconditionError(
          absl::StrCat("the SLAM job on map \"", map_, "\" has ended"));
    }
    if (mapper_ == nullptr) {
      // The mapper is made by the first task, with its worker's backend.
      early_.push_back({frame, pose, k});
      ++status_.keyframes;
      ++status_.pending_keyframes;
      status_.idle = false;
      ScheduleLocked();
      return absl::OkStatus();
    }
  }
  PLX_RETURN_IF_ERROR(mapper_->AddKeyframe(frame, pose, k));
  std::lock_guard<std::mutex> lock(mutex_);
  ++status_.keyframes;
  ++status_.pending_keyframes;
  status_.idle = false;
  ScheduleLocked();
  return absl::OkStatus();
}

SlamMapView SlamJob::View() const {
  SlamMapView view;
  std::lock_guard<std::mutex> lock(mutex_);
  if (mapper_ == nullptr) {
    view.map = base_;
    view.version = base_ ? static_cast<int64_t>(status_.map_version) : 0;
    for (const QueuedKeyframe& k : early_) view.accepted_keyframes.push_back({k.frame.timestamp, k.pose});
  } else {
    const SlamMapVersion latest = mapper_->latest();
    view.map = latest.map;
    view.version = static_cast<int64_t>(status_.map_version);
    view.accepted_keyframes = mapper_->accepted_keyframes();
    view.keyframe_poses = mapper_->keyframe_poses();
  }
  view.mapping_behind = status_.pending_keyframes > 0;
  return view;
}

SlamJobStatus SlamJob::Status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return status_;
}

void SlamJob::Enter(std::shared_ptr<SlamJobListener> listener) {
  std::lock_guard<std::mutex> lock(mutex_);
  members_.push_back(listener);
  listeners_.push_back(std::move(listener));
  status_.streams = static_cast<int>(members_.size());
}

void SlamJob::Leave(const std::shared_ptr<SlamJobListener>& listener) {
  bool finished = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = std::find(members_.begin(), members_.end(), listener);
    if (it == members_.end()) return;
    members_.erase(it);  // still notified: the last stream waits for the job's end
    status_.streams = static_cast<int>(members_.size());
    // The last stream gone: spend the rest of the budget, publish, end (RunStep).
    if (members_.empty() && !status_.finished) {
      if (worker_ == nullptr && early_.empty()) {
        FinishLocked(absl::OkStatus());  // never started: nothing to map
        finished = true;
      } else {
        ScheduleLocked();
      }
    }
  }
  // Not under the job's lock: the registry's lock comes first (SlamJobs::Join).
  if (finished) state_->slam_jobs->Remove(this);
}

void SlamJob::ScheduleLocked() {
  if (scheduled_ || status_.finished) return;
  scheduled_ = true;
  if (worker_ == nullptr) worker_ = &state_->workers->AttachStream(Priority::kBackground);
  // The task holds the job: it outlives the streams and the registry entry if it must.
  worker_->Post(Priority::kBackground,
                [self = shared_from_this()](Backend* backend, bool cancelled) {
                  self->RunStep(backend, cancelled);
                });
}

absl::Status SlamJob::PublishToStore() {
  const SlamMapVersion latest = mapper_->latest();
  if (latest.map == nullptr || latest.version == published_mapper_version_) {
    return absl::OkStatus();
  }
  const int integrated = mapper_->progress().keyframes_integrated;
  PLX_ASSIGN_OR_RETURN(const uint64_t version,
                       state_->maps->Publish(map_, latest.map, integrated - integrated_at_publish_));
  published_mapper_version_ = latest.version;
  integrated_at_publish_ = integrated;
  std::lock_guard<std::mutex> lock(mutex_);
  status_.map_version = version;
  return absl::OkStatus();
}

absl::Status SlamJob::StepMapper(Backend* backend, bool finishing, bool draining) {
  if (mapper_ == nullptr) {
    PLX_ASSIGN_OR_RETURN(std::unique_ptr<SlamMapper> mapper,
                         SlamMapper::Create(options_, backend, base_));
    std::vector<QueuedKeyframe> early;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      early = std::move(early_);
      early_.clear();
    }
    for (const QueuedKeyframe& k : early) {
      PLX_RETURN_IF_ERROR(mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
    }
    std::lock_guard<std::mutex> lock(mutex_);
    mapper_ = std::move(mapper);
    // Keyframes added between the move above and now went to early_ again: hand them over.
    for (const QueuedKeyframe& k : early_) {
      PLX_RETURN_IF_ERROR(mapper_->AddKeyframe(k.frame, k.pose, k.intrinsics));
    }
    early_.clear();
  }
  // Draining: only the keyframes already accepted are integrated; the rest of the iteration
  // budget is not spent, so the map is saved before the daemon's grace runs out.
  const bool integrate = mapper_->progress().pending_keyframes > 0;
  if (draining ? integrate : mapper_->has_work()) {
    PLX_RETURN_IF_ERROR(mapper_->Step(finishing).status());
  }
  // Out of work: what the last iterations changed is published now, not at the next keyframe
  // (a lock-step stream waits for exactly this).
  if (!mapper_->has_work() || (draining && mapper_->progress().pending_keyframes == 0)) {
    PLX_RETURN_IF_ERROR(mapper_->PublishIfChanged());
  }
  return PublishToStore();
}

void SlamJob::RunStep(Backend* backend, bool cancelled) {
  bool finishing = false;
  bool finished = false;
  const bool draining = state_->draining.load();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    scheduled_ = false;
    if (status_.finished) return;
    if (cancelled) {
      FinishLocked(absl::UnavailableError("plenoxd is shutting down"));
    }
    finishing = members_.empty() || draining;
  }
  if (cancelled) {
    state_->slam_jobs->Remove(this);
    NotifyAll();
    return;
  }
  const absl::Status status =
      CatchAllocationFailure("SLAM mapping",
                             [&] { return StepMapper(backend, finishing, draining); });
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (mapper_ != nullptr) {
      const SlamMapperProgress p = mapper_->progress();
      status_.keyframes_integrated = p.keyframes_integrated;
      status_.pending_keyframes = status_.keyframes - p.keyframes_integrated;
      status_.iterations = p.mapping_iterations;
      status_.map_bytes = p.map_bytes;
      status_.last_publish_s = p.last_publish_s;
      has_work_ = mapper_->has_work();
      // The viewer's keyframes: copied only when one more is in the map (O(keyframes) each).
      if (p.keyframes_integrated != keyframes_recorded_) {
        keyframes_recorded_ = p.keyframes_integrated;
        trajectory_->SetKeyframes(mapper_->keyframe_poses());
      }
    }
    status_.idle = !has_work_ && early_.empty() && status_.pending_keyframes == 0;
    // Draining, every keyframe accepted is in the map: nothing more to do before the save.
    const bool drained = draining && early_.empty() && status_.pending_keyframes == 0;
    if (!status.ok()) {
      LogEvent("error", "slam_mapping_failed",
               {{"map", map_}, {"job", job_id_}, {"error", status.ToString()}});
      FinishLocked(status);
    } else if (members_.empty() && (status_.idle || drained)) {
      FinishLocked(absl::OkStatus());
    } else {
      if ((has_work_ && !drained) || !early_.empty()) ScheduleLocked();
      state_->jobs->Update(job_id_, JobState::kRunning, 0.0,
                           absl::StrFormat("%d keyframes integrated, map version %d",
                                           status_.keyframes_integrated, status_.map_version));
    }
    finished = status_.finished;
  }
  if (finished) state_->slam_jobs->Remove(this);
  NotifyAll();
}

void SlamJob::FinishLocked(const absl::Status& status) {
  if (status_.finished) return;
  status_.finished = true;
  status_.error = status;
  state_->maps->EndMapping(map_);
  if (status.ok()) {
    state_->jobs->Update(job_id_, JobState::kDone, 1.0,
                         absl::StrFormat("%d keyframes, map version %d",
                                         status_.keyframes_integrated, status_.map_version));
    LogEvent("info", "slam_mapping_done",
             {{"map", map_}, {"job", job_id_},
              {"keyframes", absl::StrCat(status_.keyframes_integrated)},
              {"version", absl::StrCat(status_.map_version)}});
  } else {
    state_->jobs->Update(job_id_, JobState::kFailed, 0.0, std::string(status.message()));
  }
}

void SlamJob::NotifyAll() {
  std::vector<std::shared_ptr<SlamJobListener>> listeners;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    listeners = listeners_;
  }
  for (const std::shared_ptr<SlamJobListener>& l : listeners) l->Notify();
}

absl::StatusOr<std::shared_ptr<SlamJob>> SlamJobs::Join(const std::string& map,
                                                        const SlamMapperOptions& options,
                                                        bool mapping_set, bool deterministic,
                                                        std::shared_ptr<SlamJobListener> listener) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = jobs_.find(map);
  // A job that has just ended but is not removed yet has released the lease: start anew.
  if (it != jobs_.end() && it->second->Status().finished) {
    jobs_.erase(it);
    it = jobs_.end();
  }
  if (it != jobs_.end()) {
    std::shared_ptr<SlamJob> job = it->second;
    const MappingSessionOptions& have = job->options().mapping;
    if (mapping_set &&
        (have.iterations_per_keyframe != options.mapping.iterations_per_keyframe ||
         have.mapper.batch_size != options.mapping.mapper.batch_size ||
         have.mapper.allocation.max_depth != options.mapping.mapper.allocation.max_depth)) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "options: map \"%s\" is being mapped by a running SLAM job with "
          "iterations_per_keyframe %d, rays_per_iteration %d, max_depth %g; leave them 0 or "
          "give the same",
          map, have.iterations_per_keyframe, have.mapper.batch_size,
          have.mapper.allocation.max_depth));
    }
    if (job->deterministic() != deterministic) {
      return absl::FailedPreconditionError(absl::StrCat(
          "options.deterministic: the running SLAM job on map \"", map, "\" is ",
          job->deterministic() ? "" : "not ", "deterministic"));
    }
    job->Enter(std::move(listener));
    return job;
  }
  PLX_RETURN_IF_ERROR(state_->maps->BeginMapping(map, MappingJobKind::kSlam));
  const std::string job_id = state_->jobs->Create("slam", map);
  state_->jobs->Update(job_id, JobState::kRunning, 0.0, "waiting for keyframes");
  // A new job, a new record; over the bound, records of maps without a running job go first.
  trajectories_.erase(map);
  for (auto it = trajectories_.begin();
       it != trajectories_.end() && trajectories_.size() >= kMaxTrajectoryMaps;) {
    it = jobs_.count(it->first) == 0 ? trajectories_.erase(it) : std::next(it);
  }
  auto trajectory = std::make_shared<TrajectoryRecord>();
  trajectories_[map] = trajectory;
  auto job = std::make_shared<SlamJob>(state_, map, job_id, options, deterministic, trajectory);
  job->Enter(std::move(listener));
  jobs_[map] = job;
  LogEvent("info", "slam_mapping_started", {{"map", map}, {"job", job_id}});
  return job;
}

std::vector<std::shared_ptr<SlamJob>> SlamJobs::Running() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::shared_ptr<SlamJob>> out;
  for (const auto& [name, job] : jobs_) out.push_back(job);
  return out;
}

std::shared_ptr<SlamJob> SlamJobs::RunningOn(const std::string& map) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = jobs_.find(map);
  return it == jobs_.end() ? nullptr : it->second;
}

std::shared_ptr<const TrajectoryRecord> SlamJobs::Trajectory(const std::string& map) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = trajectories_.find(map);
  return it == trajectories_.end() ? nullptr : it->second;
}

bool SlamJobs::WaitForAll(absl::Duration timeout) const {
  const absl::Time end = absl::Now() + timeout;
  while (!Running().empty()) {
    if (absl::Now() >= end) return false;
    absl::SleepFor(absl::Milliseconds(10));
  }
  return true;
}

void SlamJobs::Remove(const SlamJob* job) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = jobs_.find(job->map());
  if (it != jobs_.end() && it->second.get() == job) jobs_.erase(it);
}

}  // namespace plx::server

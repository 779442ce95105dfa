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
                 const SlamSplitOptions& split, std::shared_ptr<TrajectoryRecord> trajectory)
    : state_(state),
      map_(std::move(map)),
      job_id_(std::move(job_id)),
      trajectory_(std::move(trajectory)) {
  status_.job_id = job_id_;
  std::shared_ptr<const PlenoxelMap> base;
  int64_t base_version = 0;
  std::shared_ptr<const MapKeyframes> saved;
  if (absl::StatusOr<MapVersion> latest = state_->maps->Latest(map_); latest.ok()) {
    base = latest->map;  // the coordinator extends it only when it has content
    base_version = static_cast<int64_t>(latest->version);
    saved = latest->keyframes;
  }
  const bool extends = base != nullptr && base->grid.num_bricks() > 0;
  // The store numbers the versions (the map's one counter): readers, the streams' updates and
  // the trackers' views all see its numbers. Each version goes with its keyframes, so a save
  // of it (a snapshot, SaveMap, the drain) has what SLAM needs to continue the map.
  SlamPublisher publish_to_store = [this](std::shared_ptr<const PlenoxelMap> version,
                                          int new_keyframes) -> absl::StatusOr<int64_t> {
    PLX_ASSIGN_OR_RETURN(const uint64_t number,
                         state_->maps->Publish(map_, std::move(version), new_keyframes,
                                               coordinator_->published_keyframes()));
    return static_cast<int64_t>(number);
  };
  coordinator_ = std::make_unique<SlamCoordinator>(split.mapper, split.gate, std::move(base),
                                                   base_version, std::move(publish_to_store));
  // The map's keyframes (its file's after a restart, or the previous job's): cameras
  // relocalise against them and keyframe counts go on from them.
  if (extends && saved != nullptr && !saved->empty()) {
    if (absl::Status seeded = coordinator_->SeedSavedKeyframes(*saved); seeded.ok()) {
      saved_keyframes_ = static_cast<int>(saved->size());
    } else {
      LogEvent("warning", "saved_keyframes_not_used",
               {{"map", map_}, {"job", job_id_}, {"reason", std::string(seeded.message())}});
    }
  }
}

SlamJob::~SlamJob() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (worker_ != nullptr) state_->workers->DetachStream(*worker_);
}

absl::Status SlamJob::Accept(const RgbdFrame& frame, const PinholeIntrinsics& k,
                             SlamFrameResult* result, int* segment, int camera) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (status_.finished) {
      return absl::FailedPreconditionError(
          absl::StrCat("the SLAM job on map \"", map_, "\" has ended"));
    }
  }
  PLX_ASSIGN_OR_RETURN(const bool queued, coordinator_->Accept(frame, k, result, segment, camera));
  if (!queued) return absl::OkStatus();
  std::lock_guard<std::mutex> lock(mutex_);
  ScheduleLocked();
  return absl::OkStatus();
}

SlamJobStatus SlamJob::Status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  SlamJobStatus s = status_;
  s.mapping = coordinator_->progress();
  return s;
}

bool SlamJob::Enter(std::shared_ptr<SlamJobListener> listener) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (status_.finished) return false;
  members_.push_back(listener);
  listeners_.push_back(std::move(listener));
  status_.streams = static_cast<int>(members_.size());
  return true;
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
      if (worker_ == nullptr) {
        FinishLocked(absl::OkStatus());  // no keyframe, no task: nothing to map
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

void SlamJob::RunStep(Backend* backend, bool cancelled) {
  SlamStepMode mode = SlamStepMode::kMap;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    scheduled_ = false;
    if (status_.finished) return;
    if (cancelled) FinishLocked(absl::UnavailableError("plenoxd is shutting down"));
    // Draining: only what was accepted goes into the map before the save. The last stream
    // gone: the rest of the budget, then the final version.
    if (state_->draining.load()) {
      mode = SlamStepMode::kDrain;
    } else if (members_.empty()) {
      mode = SlamStepMode::kFinish;
    }
  }
  if (cancelled) {
    state_->slam_jobs->Remove(this);
    NotifyAll();
    return;
  }
  // The mapper is made by the first task, with its worker's backend.
  const absl::StatusOr<SlamStepResult> step = CatchAllocationFailure(
      "SLAM mapping", [&]() -> absl::StatusOr<SlamStepResult> {
        if (!coordinator_->mapper_started()) {
          PLX_RETURN_IF_ERROR(coordinator_->StartMapper(backend));
        }
        return coordinator_->Step(mode);
      });
  bool finished = false;
  {
    const SlamMapperProgress p = coordinator_->progress();
    std::lock_guard<std::mutex> lock(mutex_);
    // The viewer's keyframes: copied only when one more is in the map or a loop closure
    // changed them (O(keyframes) each).
    if (p.keyframes_integrated != keyframes_recorded_ ||
        p.loops.accepted != loops_recorded_ || p.loops.corrections != corrections_recorded_) {
      keyframes_recorded_ = p.keyframes_integrated;
      loops_recorded_ = p.loops.accepted;
      corrections_recorded_ = p.loops.corrections;
      std::vector<std::pair<int, int>> loops;
      for (const LoopEdge& loop : coordinator_->loops()) loops.emplace_back(loop.from, loop.to);
      trajectory_->SetKeyframes(coordinator_->keyframe_poses(), loops);
    }
    if (!step.ok()) {
      LogEvent("error", "slam_mapping_failed",
               {{"map", map_}, {"job", job_id_}, {"error", step.status().ToString()}});
      FinishLocked(step.status());
    } else if (members_.empty() && step->out_of_work) {
      // Idle, or (draining) every keyframe accepted is in the map: nothing more to do.
      FinishLocked(absl::OkStatus());
    } else {
      if (!step->out_of_work) ScheduleLocked();
      state_->jobs->Update(job_id_, JobState::kRunning, 0.0,
                           absl::StrFormat("%d keyframes integrated, map version %d",
                                           p.keyframes_integrated, p.map_version));
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
    const SlamMapperProgress p = coordinator_->progress();
    state_->jobs->Update(job_id_, JobState::kDone, 1.0,
                         absl::StrFormat("%d keyframes, map version %d", p.keyframes_integrated,
                                         p.map_version));
    LogEvent("info", "slam_mapping_done",
             {{"map", map_}, {"job", job_id_},
              {"keyframes", absl::StrCat(p.keyframes_integrated)},
              {"version", absl::StrCat(p.map_version)}});
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
                                                        const SlamSplitOptions& split,
                                                        bool mapping_set,
                                                        std::shared_ptr<SlamJobListener> listener) {
  const SlamMapperOptions& options = split.mapper;
  const bool deterministic = split.gate.lock_step;
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
    // It may have ended since the check above (its task needs no registry lock for that).
    if (job->Enter(listener)) return job;
    jobs_.erase(it);
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
  auto job = std::make_shared<SlamJob>(state_, map, job_id, split, trajectory);
  job->Enter(std::move(listener));  // a new job has not ended
  jobs_[map] = job;
  LogEvent("info", "slam_mapping_started",
           {{"map", map}, {"job", job_id},
            {"saved_keyframes", absl::StrCat(job->saved_keyframes())}});
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

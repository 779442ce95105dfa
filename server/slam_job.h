// A map's SLAM mapping job: the map's SlamCoordinator (core/slam/slam_coordinator.h: the one
// SlamMapper, the gate, the step/publish/drain rules, the view) that every Slam stream on the
// map feeds with keyframes, driven by background tasks. The job adds what only the daemon has:
// the map's writer lease (so Integrate is refused meanwhile), the tasks on one device worker
// (each one coordinator Step: allocation and fusion of one keyframe, or one chunk of
// iterations), the store as the publisher that numbers each version (the map's one version
// counter), and the streams' listeners, told when something changed (a keyframe integrated, a
// version published, the job finished or failed).
//
// Lifetime: the first Slam stream on a map starts the job (SlamJobs::Join); later streams join
// it. When the last stream leaves, the job spends the rest of its iteration budget
// (SlamStepMode::kFinish), publishes the final version, releases the lease and ends. When the
// daemon drains, it steps in SlamStepMode::kDrain (only the keyframes already accepted are
// integrated) and ends, so the save has every one of them. A job is shared (shared_ptr) by its
// streams, the registry and its queued task.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_mapper.h"
#include "core/slam/slam_tracker.h"
#include "server/daemon_state.h"
#include "server/device_worker.h"
#include "server/trajectory_record.h"

namespace plx::server {

// What the streams on a map are told about its job (SlamUpdate.mapping): the coordinator's
// progress (keyframes from every stream; map_version: the store's version of the newest
// published map) and the job's own state.
struct SlamJobStatus {
  std::string job_id;
  SlamMapperProgress mapping;
  int streams = 0;
  bool finished = false;         // ended: the final version is published, the lease released
  absl::Status error;            // the job failed (every stream on it fails with this)
};

// A stream's mailbox for the job's news. The stream calls `reset` before it is destroyed; the
// job calls `notify` (never with its own lock held) while the stream exists.
class SlamJobListener {
 public:
  explicit SlamJobListener(std::function<void()> notify) : notify_(std::move(notify)) {}
  void Notify();
  void Reset();

 private:
  std::mutex mutex_;
  std::function<void()> notify_;  // empty once reset
};

class SlamJob : public std::enable_shared_from_this<SlamJob> {
 public:
  // `split`: the first stream's options (its mapper options and gate; later streams bring
  // their own max_pending_keyframes to MayCameraProceed).
  SlamJob(DaemonState* state, std::string map, std::string job_id, const SlamSplitOptions& split,
          std::shared_ptr<TrajectoryRecord> trajectory);
  ~SlamJob();

  const std::string& map() const { return map_; }
  const SlamMapperOptions& options() const { return coordinator_->mapper_options(); }
  bool deterministic() const { return coordinator_->gate().lock_step; }
  // Where the job's streams record their cameras and the job its keyframes (the web viewer's
  // view of the job); it outlives the job in the registry (SlamJobs::Trajectory).
  TrajectoryRecord& trajectory() const { return *trajectory_; }

  // Applies a camera's tracked frame (any thread; SlamCoordinator::Accept: a new segment, a
  // join, the keyframe with its relocalisation features) and schedules mapping for what it
  // queued. `segment` is the camera's, `camera` its number in trajectory() (each camera's
  // keyframes form their own chain in loop closure's pose graph).
  absl::Status Accept(const RgbdFrame& frame, const PinholeIntrinsics& k,
                      SlamFrameResult* result, int* segment, int camera);
  // What a camera in `segment` tracks against now (the newest version with the store's number
  // for the main map, keyframes accepted and refined).
  SlamMapView View(int segment = 0) const { return coordinator_->View(segment); }
  // Whether a stream whose last frame made a keyframe (or needed a version) may track its
  // next one (SlamCoordinator::MayCameraProceed with the stream's own bound).
  bool MayCameraProceed(int max_pending_keyframes, int segment = 0,
                        bool needs_version = true) const {
    return coordinator_->MayCameraProceed(max_pending_keyframes, segment, needs_version);
  }
  SlamJobStatus Status() const;
  // The main map's corrections after `generation`, oldest first
  // (SlamCoordinator::CorrectionsAfter).
  std::vector<std::shared_ptr<const SlamCorrection>> CorrectionsAfter(int generation) const {
    return coordinator_->CorrectionsAfter(generation);
  }
  // Keyframes the map had when the job started (its file's, or an earlier job's), seeded into
  // the coordinator (SlamCoordinator::SeedSavedKeyframes).
  int saved_keyframes() const { return saved_keyframes_; }

  // Stream membership (SlamJobs does the joining). A stream that leaves is still notified (it
  // may wait for the job's end); Leave is idempotent per listener. Enter refuses (false) a job
  // that has ended: checked under the job's lock, since a job's task may end it at any time.
  bool Enter(std::shared_ptr<SlamJobListener> listener);
  void Leave(const std::shared_ptr<SlamJobListener>& listener);

 private:
  friend class SlamJobs;

  void ScheduleLocked();  // posts one mapping task unless one is queued
  // One coordinator step (starting the mapper with the worker's backend first).
  void RunStep(Backend* backend, bool cancelled);
  // Marks the job ended and releases the map's lease; the caller then removes it from the
  // registry without holding mutex_ (lock order: registry, then job).
  void FinishLocked(const absl::Status& status);
  void NotifyAll();

  DaemonState* const state_;
  const std::string map_;
  const std::string job_id_;
  const std::shared_ptr<TrajectoryRecord> trajectory_;
  // The map's rules; its base is the store's map when the job started (the map to extend,
  // when it has content) and its publisher the store. Stepped by the job's task only.
  std::unique_ptr<SlamCoordinator> coordinator_;
  int saved_keyframes_ = 0;

  // Keyframes integrated, loop edges and corrections when trajectory_ last got the keyframes'
  // poses (task).
  int keyframes_recorded_ = 0;
  int loops_recorded_ = 0;
  int corrections_recorded_ = 0;

  mutable std::mutex mutex_;  // guards what follows
  std::vector<std::shared_ptr<SlamJobListener>> members_;    // the streams on the job
  std::vector<std::shared_ptr<SlamJobListener>> listeners_;  // notified: members and leavers
  DeviceWorker* worker_ = nullptr;     // bound at the first post
  bool scheduled_ = false;
  SlamJobStatus status_;  // the job's own fields (Status adds the coordinator's progress)
};

// The running SLAM jobs by map name (owned by the daemon, shared through DaemonState).
class SlamJobs {
 public:
  explicit SlamJobs(DaemonState* state) : state_(state) {}

  // Joins the map's running job, or starts one (taking the map's writer lease: FAILED_PRECONDITION
  // while Integrate holds it). A stream joining a running job must leave the mapping options at
  // their defaults or give the same values (`mapping_set`: the stream set them explicitly).
  absl::StatusOr<std::shared_ptr<SlamJob>> Join(const std::string& map,
                                                const SlamSplitOptions& options,
                                                bool mapping_set,
                                                std::shared_ptr<SlamJobListener> listener);
  // Jobs still running (for metrics and drain).
  std::vector<std::shared_ptr<SlamJob>> Running() const;
  // The running job on `map`, or null.
  std::shared_ptr<SlamJob> RunningOn(const std::string& map) const;
  // The cameras and keyframes of the map's running or last SLAM job (null: none since the
  // daemon started). Each new job on a map starts a new record; records of at most
  // kMaxTrajectoryMaps maps are kept (ended jobs' first go).
  std::shared_ptr<const TrajectoryRecord> Trajectory(const std::string& map) const;
  static constexpr size_t kMaxTrajectoryMaps = 64;
  // Drain: waits until every job has ended (they only integrate what they accepted once the
  // daemon drains and their streams are gone); false when `timeout` passed first.
  bool WaitForAll(absl::Duration timeout) const;

 private:
  friend class SlamJob;
  void Remove(const SlamJob* job);

  DaemonState* const state_;
  mutable std::mutex mutex_;
  std::map<std::string, std::shared_ptr<SlamJob>> jobs_;
  std::map<std::string, std::shared_ptr<TrajectoryRecord>> trajectories_;
};

}  // namespace plx::server

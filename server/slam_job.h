// A map's SLAM mapping job: the one SlamMapper (core/slam/slam_mapper.h) that every Slam stream
// on the map feeds with keyframes. It holds the map's writer lease (so Integrate is refused
// meanwhile), runs the mapper in bounded steps as background tasks on one device worker
// (allocation and fusion of one keyframe, or one chunk of iterations), publishes each new
// version to the map store for every reader, and tells the streams when something changed
// (a keyframe integrated, a version published, the job finished or failed).
//
// Lifetime: the first Slam stream on a map starts the job (SlamJobs::Join); later streams join
// it. When the last stream leaves, the job spends the rest of its iteration budget, publishes
// the final version, releases the lease and ends. When the daemon drains, it only integrates
// the keyframes already accepted, publishes and ends, so the save has every one of them. A job is shared (shared_ptr) by its streams,
// the registry and its queued task.
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
#include "core/slam/slam_mapper.h"
#include "core/slam/slam_tracker.h"
#include "server/daemon_state.h"
#include "server/device_worker.h"
#include "server/trajectory_record.h"

namespace plx::server {

// What the streams on a map are told about its job (SlamUpdate.mapping).
struct SlamJobStatus {
  std::string job_id;
  int keyframes = 0;             // accepted from every stream
  int keyframes_integrated = 0;
  int pending_keyframes = 0;
  int iterations = 0;
  uint64_t map_version = 0;      // the store's version of the newest published map
  int64_t map_bytes = 0;
  int streams = 0;
  bool idle = false;             // no keyframe waiting and the iteration budget spent
  bool finished = false;         // ended: the final version is published, the lease released
  absl::Status error;            // the job failed (every stream on it fails with this)
  double last_publish_s = 0.0;
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
  SlamJob(DaemonState* state, std::string map, std::string job_id, SlamMapperOptions options,
          bool deterministic, std::shared_ptr<TrajectoryRecord> trajectory);
  ~SlamJob();

  const std::string& map() const { return map_; }
  const SlamMapperOptions& options() const { return options_; }
  bool deterministic() const { return deterministic_; }
  // Where the job's streams record their cameras and the job its keyframes (the web viewer's
  // view of the job); it outlives the job in the registry (SlamJobs::Trajectory).
  TrajectoryRecord& trajectory() const { return *trajectory_; }

  // Queues a keyframe (any thread) and schedules mapping.
  absl::Status AddKeyframe(const RgbdFrame& frame, const SE3& pose, const PinholeIntrinsics& k);
  // What a camera tracks against now (the newest version, keyframes accepted and refined).
  SlamMapView View() const;
  SlamJobStatus Status() const;

  // Stream membership (SlamJobs does the joining). A stream that leaves is still notified (it
  // may wait for the job's end); Leave is idempotent per listener.
  void Enter(std::shared_ptr<SlamJobListener> listener);
  void Leave(const std::shared_ptr<SlamJobListener>& listener);

 private:
  friend class SlamJobs;
  struct QueuedKeyframe {
    RgbdFrame frame;
    SE3 pose;
    PinholeIntrinsics intrinsics;
  };

  void ScheduleLocked();  // posts one mapping task if none is queued and there is work
  void RunStep(Backend* backend, bool cancelled);
  // Steps the mapper once (creating it first); returns whether a new version went to the store.
  // Draining: only integrates the keyframes already accepted, then publishes.
  absl::Status StepMapper(Backend* backend, bool finishing, bool draining);
  absl::Status PublishToStore();
  // Marks the job ended and releases the map's lease; the caller then removes it from the
  // registry without holding mutex_ (lock order: registry, then job).
  void FinishLocked(const absl::Status& status);
  void NotifyAll();

  DaemonState* const state_;
  const std::string map_;
  const std::string job_id_;
  const SlamMapperOptions options_;
  const bool deterministic_;
  const std::shared_ptr<TrajectoryRecord> trajectory_;

  // Stepped by the job's task only (one at a time).
  std::unique_ptr<SlamMapper> mapper_;
  int64_t published_mapper_version_ = 0;  // the mapper's version last given to the store
  int integrated_at_publish_ = 0;
  int keyframes_recorded_ = 0;  // keyframes integrated when trajectory_ last got their poses

  mutable std::mutex mutex_;  // guards what follows
  std::vector<std::shared_ptr<SlamJobListener>> members_;    // the streams on the job
  std::vector<std::shared_ptr<SlamJobListener>> listeners_;  // notified: members and leavers
  std::vector<QueuedKeyframe> early_;  // keyframes added before the mapper exists
  DeviceWorker* worker_ = nullptr;     // bound at the first post
  bool scheduled_ = false;
  bool has_work_ = false;              // the mapper's, after the last step
  SlamJobStatus status_;
  // The store's map when the job started, when it had content (the map to extend), else null.
  std::shared_ptr<const PlenoxelMap> base_;
};

// The running SLAM jobs by map name (owned by the daemon, shared through DaemonState).
class SlamJobs {
 public:
  explicit SlamJobs(DaemonState* state) : state_(state) {}

  // Joins the map's running job, or starts one (taking the map's writer lease: FAILED_PRECONDITION
  // while Integrate holds it). A stream joining a running job must leave the mapping options at
  // their defaults or give the same values (`mapping_set`: the stream set them explicitly).
  absl::StatusOr<std::shared_ptr<SlamJob>> Join(const std::string& map,
                                                const SlamMapperOptions& options,
                                                bool mapping_set, bool deterministic,
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

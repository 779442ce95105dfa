// Incremental mapping (DESIGN.md §7, §10): posed keyframes arrive one at a time while readers
// use the map, so the work is cut into bounded steps and the map is published as immutable
// copy-on-write versions. This is the policy every streaming caller shares (the daemon's
// Integrate stream, SLAM): how much each keyframe earns of the iteration budget, how long one
// step may run, when a new version is worth publishing, and how a job continues a map.
//
// Threads: AddKeyframe may be called from any thread; everything else from one thread at a
// time (the step runner, e.g. the worker that owns the backend).
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapper.h"

namespace plx {

// The most iterations a keyframe may earn; beyond it a typo, not a wish.
inline constexpr int kMaxIterationsPerKeyframe = 100000;
// Iterations each keyframe earns when nobody says otherwise (the daemon's Integrate and Slam
// streams, the CLI's budget without --iterations).
inline constexpr int kDefaultIterationsPerKeyframe = 50;

struct MappingSessionOptions {
  // Voxel size, batch, learning rates and the allocation/fusion bands. The budget fields are
  // the session's: it grows max_iterations by iterations_per_keyframe per keyframe.
  MapperOptions mapper;
  int iterations_per_keyframe = kDefaultIterationsPerKeyframe;

  // One Step is either one optimisation chunk, at most chunk_iterations iterations or
  // chunk_seconds (at least one iteration), or one slice of a keyframe's integration
  // (allocation, fusion, occupancy, optimiser buffers: Mapper::IntegrateSlice), at most
  // chunk_seconds plus one piece of it. A tracking frame queued behind a step on the same device
  // waits about chunk_seconds plus one iteration or piece. One time bound for both: it is the
  // wait a tracking frame may see, whatever the mapping work is.
  int chunk_iterations = 10;
  double chunk_seconds = 0.05;
  // Iterations a keyframe just integrated gets (in chunks as above) before the map is published
  // with it and before the next keyframe's integration starts, while the budget lasts. A fused
  // but unfitted region renders surfaces seen at a grazing angle in front of where they are,
  // and a camera tracked against it lands about a centimetre off, adds a keyframe there, and
  // the next frames track against that: SLAM that outruns its mapping slides. The first
  // iterations remove most of the bias; more of them cost keyframes while mapping is behind
  // (docs/BENCHMARKS.md, "Fitted before it is published"). 1: one chunk, as before.
  int iterations_after_integration = 3;
  // Copy-on-write clones per iteration (MapperOptions::max_clones_per_iteration): 1024 bricks
  // are 56 MB, so the first iterations after a publish stay about as long as the others
  // instead of one of them cloning a third of the map.
  int max_clones_per_iteration = 1024;

  // A version is published when keyframes were integrated since the last one, or
  // publish_every_iterations iterations have run, and at least min_publish_interval_s has
  // passed; the interval stretches to 10x the last publish's cost, so publishing never takes
  // more than about a tenth of the session's time.
  double min_publish_interval_s = 1.0;
  int publish_every_iterations = 100;
};

// Checks the session's own fields and the mapper options it will use.
absl::Status ValidateMappingSessionOptions(const MappingSessionOptions& options);

struct MappingStepResult {
  int keyframes_integrated = 0;  // completed by this step (0 or 1)
  int iterations = 0;            // run by this step
  // Set when this step published a new version of the map.
  std::shared_ptr<const PlenoxelMap> published;
  int keyframes_in_published = 0;  // keyframes integrated since the previous published version
  // Where the step's time went (seconds).
  double integrate_s = 0.0, optimize_s = 0.0, publish_s = 0.0;
};

struct MappingSessionProgress {
  int keyframes_added = 0;       // AddKeyframe calls accepted
  int keyframes_integrated = 0;  // allocated and initialised in the map, every slice done
  int iterations = 0;
  // iterations_per_keyframe * keyframes integrated that earn, plus GrantIterations'
  int iteration_budget = 0;
  double fraction = 0.0;         // iterations / budget, capped at 1
  double schedule = 0.0;         // learning-rate schedule position (never decreases)
  // The last optimisation chunk's last batch: its PSNR, depth L1 and opacity (its iteration
  // and fraction are the mapper's, not the session's counters above).
  MappingProgress last_batch;
  int published_versions = 0;
  int64_t map_bytes = 0;
  int64_t cloned_bricks = 0;     // copy-on-write clones so far
  double last_publish_s = 0.0;   // how long the last publish took
};

class MappingSession {
 public:
  // A session that continues `base` (a published version, shared, never written: the session
  // maps a copy-on-write copy of it) or, when `base` is null, starts a new map with
  // options.mapper.voxel_size. `backend` must outlive the session.
  static absl::StatusOr<std::unique_ptr<MappingSession>> Create(
      const MappingSessionOptions& options, Backend* backend,
      std::shared_ptr<const PlenoxelMap> base);

  // Queues a keyframe (thread-safe; checked now, integrated by a later Step). Without
  // `earns_iterations` it is fused and trained on but adds nothing to the iteration budget: a
  // keyframe the map already fits (a loop correction's rebuild that kept what it saw).
  absl::Status AddKeyframe(RgbdFrame frame, const SE3& world_T_camera,
                           const PinholeIntrinsics& intrinsics, bool earns_iterations = true);
  int pending_keyframes() const;

  // True while a Step would do something: a keyframe is being integrated, keyframes are queued
  // or budget is left.
  bool has_work() const;

  // One bounded piece of work: a slice of the integration of one keyframe (the one in progress,
  // else the next queued one) or one chunk of iterations (when no keyframe is to be integrated,
  // and once right after each integration, before the next queued keyframe starts). Then,
  // unless an integration is in progress (its bricks are not all fused yet), publishes a version
  // when one is due. With `finish`, also publishes whatever is not published yet once no work is
  // left (the end of a job).
  absl::StatusOr<MappingStepResult> Step(bool finish = false);

  // Publishes the current map now (e.g. before a save), unless nothing changed since the last
  // version, when it returns that one. A keyframe being integrated is finished first.
  absl::StatusOr<std::shared_ptr<const PlenoxelMap>> Publish();

  // The keyframes integrated so far, in order (step-runner thread only).
  const TrainingSet& keyframes() const { return mapper_->training_set(); }
  // Moves integrated keyframe i to a refined pose; the next version publishes the change
  // (step-runner thread only).
  absl::Status SetKeyframePose(int i, const SE3& world_T_camera);
  // Adds `iterations` to the budget beyond what the keyframes earned (keyframes moved after
  // their iterations, which the map must fit again). Step-runner thread only.
  void GrantIterations(int iterations);

  MappingSessionProgress progress() const;
  // The latest published version (null before the first publish).
  const std::shared_ptr<const PlenoxelMap>& latest() const { return latest_; }

 private:
  struct PendingKeyframe {
    RgbdFrame frame;
    SE3 world_T_camera;
    PinholeIntrinsics intrinsics;
    bool earns_iterations = true;
  };

  MappingSession(const MappingSessionOptions& options, std::unique_ptr<Mapper> mapper);
  bool BudgetLeft() const;
  int Budget() const;  // what progress().iteration_budget reports
  // Mapper::IntegrateSlice, counting the keyframe once its integration completes.
  absl::Status IntegrateSlice(double max_seconds, MappingStepResult* result);
  absl::Status PublishInto(MappingStepResult* result);

  const MappingSessionOptions options_;
  std::unique_ptr<Mapper> mapper_;

  mutable std::mutex mutex_;
  std::deque<PendingKeyframe> pending_;  // guarded by mutex_
  int added_ = 0;                        // guarded by mutex_

  int integrated_ = 0;
  int earning_integrated_ = 0;     // of them, those that earn iterations
  int granted_iterations_ = 0;     // GrantIterations' sum
  bool integrating_earns_ = true;  // the keyframe being integrated earns iterations
  // Iterations still owed to the keyframe integrated last (iterations_after_integration).
  int owed_after_integration_ = 0;
  MappingProgress last_;
  std::shared_ptr<const PlenoxelMap> latest_;
  int published_versions_ = 0;
  bool changed_since_publish_ = false;
  int keyframes_since_publish_ = 0;
  int iterations_at_publish_ = 0;
  double last_publish_cost_s_ = 0.0;
  double last_publish_time_s_ = -1e300;  // on the session's clock
};

}  // namespace plx

// Online RGB-D SLAM in-process (DESIGN.md §9): unposed frames from one camera in, one pose
// per frame out while the map grows behind the tracker. A session is the two halves wired
// together with a threading mode:
//   - SlamTracker (core/slam/slam_tracker.h): bootstrap (WAITING until a frame has enough depth
//     to start the map), tracking against the latest published version, keyframe decisions,
//     relocalisation after LOST;
//   - SlamMapper (core/slam/slam_mapper.h): the keyframes' MappingSession with its local window,
//     keyframe pose refinement, published versions.
// By default mapping runs on its own thread with its own backend (optionally at a lower CPU
// priority, mapping_nice); a frame does not wait for mapping: while a keyframe waits for
// integration the tracker defers the next one (max_pending_keyframes), and the optimisation is
// never waited for. Only a keyframe deferred for SlamTrackerOptions::max_deferred_frames is
// taken anyway, and its frame waits until mapping is back within the bound. Deterministic mode
// runs mapping in lock-step on the caller's thread after each keyframe instead (bit-identical
// results run to run, for tests). The daemon wires the same halves to its workers instead
// (server/).
//
// Memory grows with the number of keyframes (their images and rays: ~16 B per pixel plus 8 B
// per pixel with valid depth, 7.4 MB for a 640x480 keyframe) and with the mapped volume (the
// grid), not with the number of frames.
//
// Threads: one caller at a time (ProcessFrame, Finish); progress(), latest_map() and
// keyframe_poses() from any thread.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "core/formats/map_keyframe.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapping_session.h"
#include "core/slam/keyframe_policy.h"
#include "core/slam/keyframe_refinement.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_mapper.h"
#include "core/slam/slam_tracker.h"
#include "core/tracking/tracker.h"

namespace plx {

// The most keyframes a camera may run ahead of mapping (SlamOptions::max_pending_keyframes):
// beyond a few, views go unmapped faster than keyframes integrate.
inline constexpr int kMaxPendingKeyframes = 4;

struct SlamOptions {
  TrackerOptions tracker;
  MappingSessionOptions mapping;
  KeyframePolicy keyframes;
  KeyframeRefinementOptions refinement;  // refinement.window = 0 turns it off
  // Loop closure and the map's rebuild at corrected poses (core/slam/loop_closure.h;
  // loop_closure.enabled = false turns it off).
  LoopClosureOptions loop_closure;

  // Lock-step mapping on the caller's thread (see above). Bit-identical results also need a
  // mapping backend whose gradient scatter has a fixed order: the CPU backend on one thread
  // (with more, atomic float adds land in a varying order).
  bool deterministic = false;
  // Concurrent mode: at most this many accepted keyframes wait for integration (allocation and
  // fusion) while the camera goes on; a frame that would be a keyframe beyond that is deferred
  // (SlamTrackerOptions::max_pending_keyframes), so no frame waits for mapping. 0: each
  // keyframe's frame waits until mapping has integrated it (the next frames track against a
  // map that has it; a frame then pays for a whole keyframe's fusion, seconds on 2 cores).
  // Without a bound, tracking outruns mapping, views go unmapped and tracking is lost.
  // At most kMaxPendingKeyframes; lock-step (deterministic) ignores it (nothing is pending).
  int max_pending_keyframes = 1;
  // The frames come at the sensor's pace whatever the tracker does (a live camera, a realtime
  // replay, a daemon stream with realtime): a frame never waits for mapping. Until the map's
  // first version is out the odometry carries the camera however long it takes
  // (SlamTrackerOptions::carry_until_version). A keyframe that mapping has no room for stays
  // deferred for as long as mapping is behind, instead of being taken after
  // SlamTrackerOptions::max_deferred_frames with its frame waiting: meanwhile the sensor's
  // frames are dropped, and the next frame tracked comes after a jump (seconds, on 2 cores)
  // that neither the odometry nor the map tracker's basin bridges (docs/BENCHMARKS.md, "A live
  // camera never waits for mapping"). A replay as fast as the engine goes (false) waits
  // instead, or it would outrun mapping for the whole run. Not with deterministic; with
  // max_pending_keyframes 0 each keyframe's frame still waits for its integration (asked for).
  bool live_source = false;
  // Concurrent mode: the mapping thread's nice increment (Linux; 0 = same priority as the
  // tracker). Its backend's worker threads inherit it. 10 by default, as the daemon's mapping
  // worker: at the same priority the tracker's and the mapper's threads share 2 cores evenly
  // and each frame's map tracking took 2.5x as long (docs/BENCHMARKS.md, issue 21's speed
  // section). Before frames stopped waiting for keyframes (max_pending_keyframes), nice 10
  // starved the optimisation on the synthetic room and about doubled its ATE ("Online SLAM").
  int mapping_nice = 10;

  // Keyframe poses tried besides the last good pose when relocalising.
  int relocalisation_keyframes = 4;
  // An attempt that ends further than this from its starting pose is a false match.
  double relocalisation_radius_m = 0.25;
  // The front-end's parts (SlamTrackerOptions): the map-free odometry and relocalisation by
  // keyframe features. Both on by default; off only to measure what each brings.
  bool odometry = true;
  bool feature_relocalisation = true;
  // Map segments (SlamTrackerOptions): LOST frames with depth before a camera starts a segment
  // of its own (0: never), the same for frames chained to a map pose the features did not
  // confirm, and frames between its attempts to find the main map again.
  int new_segment_after_lost_frames = 10;
  int new_segment_after_unconfirmed_frames = 30;
  int segment_join_interval = 5;
  // The map tracker's time per frame against its running median (SlamTrackerOptions; 0: off).
  double map_time_budget = 1.3;

  // Where keyframe 0 sits (world_T_camera); the frame's prior wins, else the identity.
  std::optional<SE3> initial_pose;
};

// The defaults SLAM uses: the mapping window on, publishing as soon as a keyframe is in.
SlamOptions DefaultSlamOptions();
// The defaults at a voxel size (the mapper's lengths that scale with it) with `tracker`, which
// keyframe refinement follows too (with at least its own iteration count). Every front end
// (plenox slam, the daemon's Slam stream) starts from this.
SlamOptions SlamOptionsFor(float voxel_size, const TrackerOptions& tracker);

// InvalidArgument naming the field.
absl::Status ValidateSlamOptions(const SlamOptions& options);

// The halves' options: SplitSlamOptions (core/slam/slam_coordinator.h).

// The session's counters: the camera's (SlamTracker::counts) and the map's
// (SlamCoordinator::progress), each as its half keeps it.
struct SlamProgress {
  SlamTrackerCounts tracking;  // frames, and how each was tracked
  SlamMapperProgress mapping;  // keyframes, their integration, the map's version and size
  SlamSegmentCounts segments;  // map segments started and joined (SlamCoordinator::segments)
};

class SlamSession {
 public:
  using BackendFactory = std::function<absl::StatusOr<std::unique_ptr<Backend>>()>;

  // `tracking_backend` must outlive the session. `make_mapping_backend` is called once, on the
  // mapping thread (concurrent mode) or here (deterministic mode). `base`: an existing map to
  // extend (shared, never written), or null for a new one.
  static absl::StatusOr<std::unique_ptr<SlamSession>> Create(
      const SlamOptions& options, Backend* tracking_backend,
      const BackendFactory& make_mapping_backend,
      std::shared_ptr<const PlenoxelMap> base = nullptr);
  ~SlamSession();  // abandons mapping work not finished (call Finish to keep it)

  SlamSession(const SlamSession&) = delete;
  SlamSession& operator=(const SlamSession&) = delete;

  // Tracks one frame and hands it to mapping when it makes a keyframe. Errors are the
  // backend's, the mapping thread's or bad input (sizes, non-finite prior): a frame that cannot
  // be tracked is a LOST result.
  absl::StatusOr<SlamFrameResult> ProcessFrame(RgbdFrame frame, const PinholeIntrinsics& k,
                                               const std::optional<SE3>& prior = std::nullopt);

  // Takes no more frames; mapping integrates the keyframes accepted, spends their iteration
  // budget and publishes the final version.
  absl::Status Finish();

  std::shared_ptr<const PlenoxelMap> latest_map() const;
  // latest_map()'s keyframes as a map file keeps them (SlamCoordinator::published_keyframes),
  // so a saved map can be continued (core/formats/map_file.h).
  std::shared_ptr<const MapKeyframes> latest_map_keyframes() const {
    return coordinator_.published_keyframes();
  }
  // Keyframe poses as refined so far (timestamp, world_T_camera), in keyframe order.
  std::vector<StampedPose> keyframe_poses() const;
  // The loop edges in the map's pose graph (keyframe indices; docs/SLAM.md, "Loop closure").
  std::vector<LoopEdge> loops() const;
  SlamProgress progress() const;

 private:
  SlamSession(const SlamOptions& options, Backend* tracking_backend,
              std::shared_ptr<const PlenoxelMap> base);

  absl::Status StartMapping(const BackendFactory& make_backend);
  // The mapping thread (concurrent mode): the coordinator's steps whenever there is work.
  void MappingLoop(const BackendFactory& make_backend, std::promise<absl::Status>* started);
  // Steps until the coordinator is out of work (or the session stops) (lock-step mode, Finish).
  absl::Status RunMappingToEnd(bool finish);
  // After the coordinator queued mapping work for a frame (a keyframe, a segment's join): wakes
  // mapping, maps it (lock-step) and, after a keyframe, waits until the camera may go on
  // (SlamCoordinator::MayCameraProceed).
  absl::Status AfterQueued(bool keyframe);
  // Waits until the camera may track its next frame in its segment (SlamCoordinator::
  // MayCameraProceed; concurrent mode), or mapping failed or stopped (an error).
  absl::Status WaitForMapping(bool needs_version);
  absl::Status MappingError() const;
  void NotifyChanged();

  const SlamOptions options_;
  const SlamSplitOptions split_;
  SlamTracker tracker_;  // the caller's thread
  int segment_ = 0;      // the camera's map segment (SlamCoordinator::Accept); caller's thread
  bool finished_ = false;

  // Created on the mapping thread (concurrent mode; its nice value applies to the backend's
  // workers) or in Create (lock-step). Declared before the coordinator, whose mapper uses it.
  std::unique_ptr<Backend> mapping_backend_;
  SlamCoordinator coordinator_;  // stepped by the mapping thread or in lock-step
  std::thread mapping_thread_;

  mutable std::mutex mutex_;  // guards what follows
  std::condition_variable changed_;
  bool stop_ = false;        // leave now
  bool finishing_ = false;   // leave once the work is done
  bool mapping_done_ = false;
  uint64_t wakeups_ = 0;     // bumped when a keyframe is queued
  absl::Status mapping_error_;
  SlamTrackerCounts counts_;  // the tracker's, copied after each frame for progress()
};

}  // namespace plx

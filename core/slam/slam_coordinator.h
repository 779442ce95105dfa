// The SLAM rules that join the tracking halves (SlamTracker, one per camera) to the map's one
// mapping half (SlamMapper), written once for every driver: SlamSession (in-process, a mapping
// thread or lock-step on the caller's thread) and the daemon (server/slam_job.h: worker tasks,
// many cameras per map). The coordinator starts no thread and waits for nothing; its callers
// supply the threads or tasks and the waiting (they re-check MayCameraProceed when Step or
// AddKeyframe has changed something). It owns:
//   - the split of one SlamOptions into the halves' options (SplitSlamOptions), with lock-step
//     mapping's publishing and cloning rules as a named policy (ApplyLockStepMappingPolicy);
//   - the mapper, created with the step-runner's backend (StartMapper), and the keyframes that
//     arrive before it exists;
//   - the gate: whether a camera whose last frame made a keyframe (or that needs a version)
//     may track its next frame (MayCameraProceed);
//   - the mapper's drive loop, one bounded Step at a time: step, publish once out of work, and
//     the drain rule (integrate only the keyframes accepted, then publish) as a StepMode;
//   - the map's one version counter: each published map gets the number its publisher gives it
//     (the daemon's store) or the mapper's own, and the view a tracker reads pairs that number
//     with that map (View);
//   - map segments (docs/SLAM.md, "Map segments"): segment 0 is the main map; a camera that
//     lost it for good starts another (SlamFrameResult::new_segment), a map of its own with its
//     own mapper, stepped after the main one; when the camera finds the main map again
//     (SlamFrameResult::main_T_segment) the segment's keyframes move into the main map at the
//     joined poses and the segment ends. Accept applies a camera's frame result to all this.
//     Only the main map is published (the daemon's store, latest()); a segment never joined is
//     left out of it (segments() says how many).
//   - loop closure on the main map (docs/SLAM.md, "Loop closure"; core/slam/loop_closure.h):
//     each integrated keyframe is searched for a loop on the step-runner; a verified loop goes
//     into the pose graph, and a solve that moves the keyframes starts a rebuild: a second
//     mapper fed every keyframe at its corrected pose (and every keyframe accepted meanwhile,
//     moved with the keyframe it is anchored to), stepped in turn with the main one so
//     tracking never waits for it. Once it has integrated them all and spent
//     rebuild_iteration_share of its budget it replaces the main mapper and its map is
//     published as one version with a SlamCorrection (View().correction): cameras move with
//     it before their next frame, and a keyframe tracked in the old frame is moved into the
//     new one when it is accepted. A solve whose surfaces move no further than
//     in_place_max_shift_m is applied in the running map instead (CorrectInPlace): no rebuild,
//     the same SlamCorrection, published at once.
//   - a base map's saved keyframes (SeedSavedKeyframes: a map file's, or the daemon's previous
//     job's): the main map's keyframe list starts with them, and every published version
//     carries the list a map file keeps (published_keyframes).
//
// Threads: AddKeyframe, View, MayCameraProceed and the accessors from any thread (an internal
// lock guards the coordinator's state; the mapper has its own); StartMapper and Step from one
// step-runner at a time. The publisher is called by Step without the coordinator's lock.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "absl/status/statusor.h"
#include "core/formats/map_keyframe.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/slam/loop_closure.h"
#include "core/slam/slam_correction.h"
#include "core/slam/slam_mapper.h"
#include "core/slam/slam_tracker.h"

namespace plx {

struct SlamOptions;  // core/slam/slam_session.h

// When a camera may go on after a keyframe (MayCameraProceed).
struct SlamGateOptions {
  // Lock-step: the next frame waits until mapping has spent the keyframe's iterations and
  // published (deterministic mode: the results do not depend on timing).
  bool lock_step = false;
  // Otherwise: accepted keyframes still waiting for integration that a camera may run ahead by
  // (SlamOptions::max_pending_keyframes).
  int max_pending_keyframes = 0;
};

// One SlamOptions cut into what each part reads.
struct SlamSplitOptions {
  SlamTrackerOptions tracker;  // every camera's
  SlamMapperOptions mapper;    // the map's (ApplyLockStepMappingPolicy applied when lock-step)
  SlamGateOptions gate;
};

// Lock-step mapping publishes only when the camera's frame waits for it (out of work), clones
// every brick it needs, and bounds its chunks and pose-graph solves by iterations, not wall
// time (kLockStepUnreachedSeconds): none may depend on the clock, or runs would differ.
inline constexpr double kLockStepUnreachedSeconds = 600.0;
void ApplyLockStepMappingPolicy(SlamMapperOptions* options);

// The halves' options: the fields copied as they are, then (deterministic) the lock-step
// policy above; the tracker's bootstrap counts depth both halves use.
SlamSplitOptions SplitSlamOptions(const SlamOptions& options);

// What one Step does.
enum class SlamStepMode {
  kMap,     // a step while there is work; publishes once out of work
  kFinish,  // the same, and the last steps publish whatever is left (no more keyframes come)
  kDrain,   // kFinish for the keyframes accepted only: integrates them, then publishes (the
            // rest of the iteration budget is not spent)
};

struct SlamStepResult {
  bool stepped = false;     // the mapper did a step
  bool published = false;   // a new version is out (and given a number)
  bool out_of_work = false; // nothing left for this mode until a keyframe comes
};

// The map's segments besides the main one (SlamCoordinator::segments).
struct SlamSegmentCounts {
  int started = 0;  // segments cameras started
  int joined = 0;   // of them, moved into the main map
};

// Gives a newly published map its number (the daemon: the store's version); `new_keyframes`
// were integrated since the last one it was given.
using SlamPublisher = std::function<absl::StatusOr<int64_t>(
    std::shared_ptr<const PlenoxelMap> map, int new_keyframes)>;

class SlamCoordinator {
 public:
  // `base`: an existing map to extend (shared, never written) with its number
  // (`base_version`), or null for a new map. `publisher` null: versions are the mapper's own
  // numbers (1, 2, ...).
  SlamCoordinator(const SlamMapperOptions& mapper_options, const SlamGateOptions& gate,
                  std::shared_ptr<const PlenoxelMap> base = nullptr, int64_t base_version = 0,
                  SlamPublisher publisher = nullptr);

  SlamCoordinator(const SlamCoordinator&) = delete;
  SlamCoordinator& operator=(const SlamCoordinator&) = delete;

  const SlamMapperOptions& mapper_options() const { return mapper_options_; }
  const SlamGateOptions& gate() const { return gate_; }

  // The keyframes the base map was built from (core/formats/map_keyframe.h: its file's, or
  // what the previous job on it published): the main map's keyframes start with them. Cameras
  // relocalise against their features, the keyframe policy counts them (a view they cover adds
  // no keyframe), and every count and index of the main map's keyframes includes them, first
  // (View, keyframe_poses, loops, progress, published_keyframes). They are not mapped again
  // (the base holds what they built) and take no part in loop closure (their images are not
  // kept). Before StartMapper and before any keyframe; once; only with a base map
  // (FailedPrecondition otherwise).
  absl::Status SeedSavedKeyframes(MapKeyframes saved);

  // Creates the mapper on `backend` (it must outlive the coordinator) and hands it the
  // keyframes added before. Step-runner; once.
  absl::Status StartMapper(Backend* backend);
  bool mapper_started() const;

  // Queues a keyframe of `segment` (any thread); until the step-runner made that segment's
  // mapper it waits in the coordinator. `features` (SlamFrameResult::features) are kept for
  // relocalisation; null: this keyframe has none.
  // `unconfirmed`: SlamFrameResult::unconfirmed (loop closure's doubt in the edge into it).
  // `camera`: the camera that took it (any number the caller keeps per camera, >= 0): loop
  // closure's odometry edge into it comes from that camera's previous keyframe in the map
  // (SequentialLink); -1: from the keyframe accepted just before.
  absl::Status AddKeyframe(const RgbdFrame& frame, const SE3& pose, const PinholeIntrinsics& k,
                           std::shared_ptr<const FrameFeatures> features = nullptr,
                           int segment = 0, UnconfirmedMotion unconfirmed = {},
                           int camera = -1);

  // Applies a camera's tracked frame (any thread): starts the segment it asked for, joins its
  // segment to the main map, queues its keyframe; `segment` is the camera's (0 at first),
  // updated, and result->segment says where result->pose is; `camera` as for AddKeyframe.
  // Returns whether mapping work was queued (a keyframe or a join).
  absl::StatusOr<bool> Accept(const RgbdFrame& frame, const PinholeIntrinsics& k,
                              SlamFrameResult* result, int* segment, int camera = -1);

  // One bounded step of `mode` (StartMapper first). Step-runner.
  absl::StatusOr<SlamStepResult> Step(SlamStepMode mode);

  // What a camera in `segment` tracks against now: the newest numbered version, the keyframes
  // as accepted and as refined with their features, and whether mapping is behind; a segment's
  // view carries the main map's too.
  SlamMapView View(int segment = 0) const;

  // Whether a camera waiting after a keyframe (or for a first version) may track its next
  // frame in `segment`: at most gate.max_pending_keyframes keyframes wait for integration
  // there, the segment has a version when the camera needs one (`needs_version`: SlamTracker::
  // CarriesWithoutMap is false), and in lock-step mapping is idle.
  bool MayCameraProceed(int segment = 0, bool needs_version = true) const;
  // The same with a camera's own bound (the daemon: each stream gives its own; lock-step is
  // the map's).
  bool MayCameraProceed(int max_pending_keyframes, int segment, bool needs_version) const;

  // Mapping's counters: keyframes include those waiting for the mapper, map_version is the
  // map's number (as in View), idle says no keyframe waits and the budget is spent.
  SlamMapperProgress progress() const;
  SlamMapVersion latest() const;  // the newest version with its number (View's map)
  std::vector<StampedPose> keyframe_poses() const;  // as refined so far, in order
  SlamSegmentCounts segments() const;
  // The main map's latest loop-closure correction (null: none).
  std::shared_ptr<const SlamCorrection> correction() const;
  // The main map's corrections after `generation` (a camera's SlamFrameResult::
  // correction_generation), oldest first: what a camera whose last frame was tracked in that
  // frame has not followed, such as the corrections of a map finishing after a stream's last
  // frame. The newest kKeptCorrections are kept; a camera further behind gets none (empty)
  // rather than a chain with a gap.
  static constexpr int kKeptCorrections = 64;
  std::vector<std::shared_ptr<const SlamCorrection>> CorrectionsAfter(int generation) const;
  // The loop edges in the main map's pose graph now (keyframe indices; the viewer draws them).
  std::vector<LoopEdge> loops() const;
  // The odometry edge into each keyframe of the main map's pose graph (the keyframes accepted
  // in this run, in order: the saved ones are not in the graph): where it comes from, its doubt.
  std::vector<SequentialLink> sequential_links() const;
  // The main map's keyframes in its newest published version as a map file keeps them
  // (MapFileState): the saved ones, then each keyframe mapping integrated into that version at
  // its refined pose with its features. Set before the publisher is called with the version,
  // so the publisher may read it; never null (empty before the first version). Any thread.
  std::shared_ptr<const MapKeyframes> published_keyframes() const;

 private:
  struct EarlyKeyframe {
    RgbdFrame frame;
    SE3 pose;
    PinholeIntrinsics intrinsics;
    int camera = -1;  // Accept's (kept: a join chains the keyframes in the main map by it)
  };
  // One map: the main one (segments_[0]) or a camera's segment.
  struct Segment {
    std::unique_ptr<SlamMapper> mapper;  // made by the step-runner (StartMapper, Step)
    std::vector<EarlyKeyframe> early;    // added before the mapper exists
    // Every accepted keyframe's features, in the order accepted (immutable once shared).
    std::vector<std::shared_ptr<const FrameFeatures>> features;
    // ...and the odometry edge into each (LoopClosureGraph's), and each camera's newest
    // keyframe here (the next one's edge comes from it).
    std::vector<SequentialLink> links;
    std::unordered_map<int, int> last_keyframe_of_camera;
    // A segment's keyframes as accepted (not the main map's): what a join moves. A copy of
    // what its mapper holds: the mapper's frames belong to the step-runner, a join happens on
    // a camera's thread.
    std::vector<EarlyKeyframe> kept;
    SlamMapVersion published;     // the newest map with the number for it
    bool has_work = false;        // the mapper's, after the last step (or a keyframe)
    SlamMapperProgress progress;  // the mapper's after the last step, our numbering
    bool joined = false;          // moved into the main map; its mapper goes at the next step
    // Step-runner only.
    int64_t handed_mapper_version = 0;  // the mapper's version last given a number
    int integrated_at_publish = 0;
    // Without a publisher: added to the mapper's own numbers (a rebuilt map's mapper counts
    // from 1 again; the map's numbers go on).
    int64_t version_offset = 0;

    // Loop closure (the main map only). Step-runner:
    int loop_checked = 0;          // keyframes searched for a loop so far
    bool correction_due = false;   // a loop was accepted since the last solve
    bool correction_deferred = false;  // ...and waits for min_keyframes_between_rebuilds
    int rebuilt_at = -1;           // the keyframes when the last rebuild started
    bool step_rebuild_next = false;
    bool rebuild_refined = false;  // the rebuild's keyframes were aligned to it (once)
    // Per keyframe of the rebuild's solve: 1 = the solve moved it (the rebuild refines those);
    // empty: a rebuild from nothing, which refines every keyframe.
    std::vector<uint8_t> rebuild_moved;
    // Guarded by the coordinator's lock (written by the step-runner):
    std::vector<LoopEdge> loops;   // verified and not rejected, in keyframe indices
    std::unique_ptr<SlamMapper> rebuild;  // the map at corrected poses, being built
    // The solve the rebuild is built from (before: the poses it saw; after: corrected): a
    // keyframe accepted while it runs reaches the rebuild moved by it.
    std::shared_ptr<const SlamCorrection> rebuild_solve;
    bool rebuild_collecting = false;       // the rebuild is being filled outside the lock...
    std::vector<EarlyKeyframe> rebuild_backlog;  // ...and these came meanwhile
    // The last kKeptCorrections published, oldest first.
    std::deque<std::shared_ptr<const SlamCorrection>> corrections;
    // The latest published (null: none).
    std::shared_ptr<const SlamCorrection> correction() const {
      return corrections.empty() ? nullptr : corrections.back();
    }
  };

  bool IdleLocked(const Segment& segment) const;
  // Numbers `correction` after the main map's latest, makes it the latest and keeps it among
  // its recent ones.
  void RecordCorrectionLocked(Segment& main, std::shared_ptr<SlamCorrection> correction);
  // After a correction: the main segment now serves `latest` of `mapper` as version `number`
  // (the published map, the version numbering and the progress follow it). Under mutex_.
  void AdoptCorrectedVersionLocked(Segment& main, const SlamMapper& mapper,
                                   const SlamMapVersion& latest, int64_t number);
  SlamMapView ViewLocked(int segment) const;
  // `generation`: the main map's frame `pose` is in (SlamFrameResult::correction_generation);
  // a pose from before the latest correction moves with it.
  absl::Status AddKeyframeLocked(const RgbdFrame& frame, const SE3& pose,
                                 const PinholeIntrinsics& k,
                                 std::shared_ptr<const FrameFeatures> features,
                                 const UnconfirmedMotion& unconfirmed, int camera, Segment* to,
                                 bool keep, int generation);
  // Moves `segment`'s keyframes into the main map at main_T_segment times their poses
  // (main_T_segment measured in the main map's frame `generation`).
  absl::Status JoinLocked(int segment, const SE3& main_T_segment, int generation);
  int CurrentGenerationLocked() const;  // the main map's corrections so far
  // The segment Step works on in `mode` (the main map when none has work; `main` says whether
  // it is), the segments' mappers made if needed.
  absl::StatusOr<Segment*> SegmentToStep(SlamStepMode mode, bool* main);
  // One step of `segment` (the main map: index 0) in `mode`.
  absl::StatusOr<SlamStepResult> StepSegment(Segment* segment, bool main, SlamStepMode mode);
  // Loop closure after a main-map step: searches the newly integrated keyframes, solves the
  // pose graph when a loop was accepted and starts a rebuild when the solve moved keyframes.
  absl::Status CloseLoops(SlamStepMode mode);
  // Solves the graph and starts the rebuild (the main mapper has nothing pending).
  absl::Status CorrectAndRebuild(SlamMapper* mapper);
  // Applies a correction in the running map (SlamMapperOptions::in_place_max_shift_m): moves
  // the keyframes, grants iterations for the `moved` ones and publishes the map with the
  // correction. Step-runner.
  absl::Status CorrectInPlace(SlamMapper* mapper, const SlamCorrection& solve, int moved);
  // What a rebuild after `moves` of the keyframes at `before` starts from (SlamMapperOptions::
  // rebuild_keeps_unmoved): the old map without what moved, or nothing (an empty seed).
  // Step-runner.
  absl::StatusOr<RebuildSeed> SeedFor(SlamMapper* mapper, const std::vector<SE3>& before,
                                      const KeyframeMoves& moves);
  // One step of the rebuild; once it is ready, swaps it in and publishes it.
  absl::StatusOr<SlamStepResult> StepRebuild();
  absl::StatusOr<SlamStepResult> SwapInRebuild();
  // The saved keyframes, then what `mapper` (the main map's, whose version is being published)
  // integrated, with their features: published_keyframes() from now on. Step-runner.
  void SetPublishedKeyframes(const SlamMapper& mapper);
  // The main map's keyframe lists with the saved keyframes first.
  template <typename T>
  static std::vector<T> AfterSaved(const std::vector<T>& saved, std::vector<T> rest);

  const SlamMapperOptions mapper_options_;
  const SlamGateOptions gate_;
  const SlamPublisher publisher_;
  std::shared_ptr<const PlenoxelMap> base_;
  Backend* backend_ = nullptr;  // StartMapper's; step-runner only

  mutable std::mutex mutex_;  // guards what follows (before the mappers' own locks)
  std::vector<std::unique_ptr<Segment>> segments_;  // [0]: the main map; never shrinks
  bool started_ = false;                            // StartMapper ran
  SlamSegmentCounts segment_counts_;
  SlamLoopCounts loop_counts_;
  // SeedSavedKeyframes': as given, and their poses and features as views list them.
  MapKeyframes saved_;
  std::vector<StampedPose> saved_poses_;
  std::vector<std::shared_ptr<const FrameFeatures>> saved_features_;
  std::shared_ptr<const MapKeyframes> published_keyframes_ = std::make_shared<MapKeyframes>();
};

}  // namespace plx

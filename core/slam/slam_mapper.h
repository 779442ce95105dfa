// The mapping half of SLAM for one map (DESIGN.md §9): keyframes from one or more cameras in,
// published copy-on-write versions out. It owns the map's MappingSession (allocation, fusion,
// the windowed optimisation) and the keyframe pose refinement that alternates with it, and it
// keeps what every camera tracking in this map needs to see: the latest version and its
// number, the keyframes as accepted (for the keyframe policy, so a camera revisiting a place
// another camera mapped adds no keyframe) and as refined (for relocalisation).
//
// Work is cut into bounded steps (Step) so a caller can run them on a thread of its own
// (SlamSession), in lock-step after each keyframe (deterministic mode), or as short tasks on a
// device worker between tracking frames (the daemon).
//
// Threads: AddKeyframe and the accessors from any thread; Step, RunToEnd and PublishIfChanged
// from one step-runner thread at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapping_session.h"
#include "core/slam/keyframe_refinement.h"
#include "core/slam/loop_closure.h"
#include "core/slam/rebuild_seed.h"

namespace plx {

struct SlamMapperOptions {
  MappingSessionOptions mapping;
  KeyframeRefinementOptions refinement;  // refinement.window = 0 turns it off
  // Loop closure on the main map (SlamCoordinator; loop_closure.enabled = false turns it off).
  LoopClosureOptions loop_closure;
  // A map rebuilt at corrected poses replaces the published one once every keyframe is
  // integrated and it has run this share of its iteration budget (it spends the rest after).
  double rebuild_iteration_share = 0.5;
  // Before it replaces the main mapper, a rebuild aligns every keyframe (not only the
  // refinement window) to the map it built at the pose graph's poses, with refinement's
  // tracker and limits: the graph spreads a loop's error along the chain as the odometry's
  // noise model says, while the images tell where each keyframe really was (docs/SLAM.md,
  // "Loop closure").
  bool rebuild_refines_all = true;
  // A correction that moves no keyframe's surface points further than this (metres) is not
  // rebuilt but applied in place, as refinement applies its own (up to
  // refinement.max_translation_m, the same 5 cm): the keyframes move in the running map, the
  // ones that moved more than rebuild_seed's tolerance earn rebuild_iteration_share of their
  // iterations again to fit the map to them, and the map is published at once with the
  // correction. A larger one, whose surfaces land outside what was fitted, rebuilds the map.
  // 0: every correction rebuilds.
  double in_place_max_shift_m = 0.05;
  // A rebuild starts from the old map without what the keyframes the solve moved saw, and only
  // those keyframes earn iterations and are refined (core/slam/rebuild_seed.h). Off: on the
  // two-lap loop the graph moves nearly every keyframe, so it saved 5-7 % of the time for
  // 11-18 % more depth L1 (docs/BENCHMARKS.md, "Loop closure"). False: from nothing, every
  // keyframe earning.
  bool rebuild_keeps_unmoved = false;
  RebuildSeedOptions rebuild_seed;
};

absl::Status ValidateSlamMapperOptions(const SlamMapperOptions& options);

// A published version and its number (1, 2, ...; 0 with a null map before the first).
struct SlamMapVersion {
  std::shared_ptr<const PlenoxelMap> map;
  int64_t version = 0;
};

// Loop closure's counters (SlamCoordinator, the main map's).
struct SlamLoopCounts {
  int checked = 0;      // keyframes searched for a loop
  int proposed = 0;     // candidates place recognition ranked (above the similarity floor)
  int verified = 0;     // of them, passed the features' and the dense check
  int rejected = 0;     // failed a check, or the pose graph's
  int accepted = 0;     // loop edges in the pose graph now
  int corrections = 0;  // corrected maps published (rebuilds swapped in, or in place)
  int in_place = 0;     // of them, applied in the running map without a rebuild
  int rebuilds_abandoned = 0;  // a drain (the daemon's shutdown) came first
  bool rebuilding = false;     // a map at corrected poses is being built
  int rebuild_iterations = 0;  // its iterations so far, of the budget its keyframes earned
  int rebuild_iteration_budget = 0;
  double last_solve_ms = 0.0;  // the last pose-graph solve
  double last_shift_m = 0.0;   // the largest keyframe move it made
  // Sequential edges the two keyframes' images aligned (MeasureSequentialLink), and how many
  // of them the last solve used instead of tracking's relative pose (LoopClosureEdges).
  int links_measured = 0;
  int last_measured_edges = 0;
  // The last rebuild's seed: keyframes the solve moved (fused and trained again) and bricks of
  // the old map it kept and dropped (all dropped for a rebuild from nothing).
  int last_moved_keyframes = 0;
  int64_t last_kept_bricks = 0;
  int64_t last_dropped_bricks = 0;
};

struct SlamMapperProgress {
  int keyframes = 0;              // accepted (AddKeyframe calls that succeeded)
  int keyframes_integrated = 0;   // allocated and initialised in the map
  int pending_keyframes = 0;      // accepted, not yet integrated (mapping lag)
  int mapping_iterations = 0;
  int iteration_budget = 0;       // what the integrated keyframes earned (MappingSession)
  int refined_keyframes = 0;      // pose updates applied by refinement
  int64_t map_version = 0;
  int64_t map_bytes = 0;
  int64_t keyframe_bytes = 0;     // images and ray lists kept for mapping
  double last_publish_s = 0.0;    // how long the last publish took
  // No keyframe waiting and the iteration budget spent, the last version published
  // (SlamCoordinator::progress; the mapper's own progress leaves it false).
  bool idle = false;
  SlamLoopCounts loops;  // SlamCoordinator's; the mapper's own leaves them 0
};

// Bytes a keyframe keeps for mapping: float RGB + float depth per pixel, and two 32-bit ray
// indices per pixel with valid depth (core/mapping/training_set.h).
int64_t SlamKeyframeBytes(const RgbdFrame& frame);

class SlamMapper {
 public:
  // `backend` must outlive the mapper. `base`: an existing map to extend (shared, never
  // written; it is version 1), or null for a new map whose first keyframe builds version 1.
  static absl::StatusOr<std::unique_ptr<SlamMapper>> Create(
      const SlamMapperOptions& options, Backend* backend,
      std::shared_ptr<const PlenoxelMap> base = nullptr);

  // Queues a keyframe at `pose` (any thread): it is checked now and integrated by a later step.
  // Without `earns_iterations` it adds nothing to the iteration budget
  // (MappingSession::AddKeyframe).
  absl::Status AddKeyframe(const RgbdFrame& frame, const SE3& pose, const PinholeIntrinsics& k,
                           bool earns_iterations = true);

  // One bounded step (MappingSession::Step): a slice of one keyframe's integration or one chunk
  // of iterations, publishes a version when one is due and, once the new keyframes have had their
  // iterations, refines the window's poses. With `finish`, publishes whatever is left once no
  // work remains. Returns whether a new version was published. Step-runner thread.
  absl::StatusOr<bool> Step(bool finish = false);
  // Steps until no work is left, then publishes what changed. Step-runner thread.
  absl::Status RunToEnd(bool finish);
  // Publishes the current map if anything changed since the last version. Step-runner thread.
  absl::Status PublishIfChanged();
  // Aligns every keyframe but the first to the newest published version (refinement's
  // tracker and limits, whatever its window) and moves it; the next steps fit the map to the
  // new poses. With `only` [keyframes], just those flagged. Step-runner.
  absl::StatusOr<KeyframeRefinementResult> RefineAllKeyframes(
      const std::vector<uint8_t>& only = {});
  // Moves every integrated keyframe to `poses` (one each) and grants the map `extra_iterations`
  // to fit them (a correction applied in place). Step-runner.
  absl::Status MoveKeyframes(const std::vector<SE3>& poses, int extra_iterations);
  // True while a step would do something (keyframes queued or iteration budget left).
  // Step-runner thread.
  bool has_work() const;

  // Any thread.
  SlamMapVersion latest() const;
  std::vector<StampedPose> accepted_keyframes() const;  // poses as accepted, in order
  std::vector<StampedPose> keyframe_poses() const;      // as refined so far, in order
  // Every accepted keyframe's pose: as refined when integrated, else as accepted.
  std::vector<SE3> all_keyframe_poses() const;
  SlamMapperProgress progress() const;
  // The keyframes integrated so far with their images (loop closure, rebuilds). Step-runner.
  const TrainingSet& integrated_keyframes() const { return mapping_->keyframes(); }

 private:
  SlamMapper(const SlamMapperOptions& options, Backend* backend,
             std::unique_ptr<MappingSession> mapping, std::shared_ptr<const PlenoxelMap> base);
  // Records a step: a new version, progress, refinement.
  absl::Status AfterStep(std::shared_ptr<const PlenoxelMap> published);

  const SlamMapperOptions options_;
  Backend* const backend_;
  const std::unique_ptr<MappingSession> mapping_;
  int refined_upto_keyframes_ = 0;  // integrated keyframes the last refinement saw (runner)

  mutable std::mutex mutex_;  // guards what follows
  SlamMapVersion latest_;
  std::vector<StampedPose> accepted_;
  std::vector<StampedPose> refined_;
  SlamMapperProgress progress_;
};

}  // namespace plx

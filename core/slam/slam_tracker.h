// The tracking half of SLAM for one camera (DESIGN.md §9): each frame against the latest
// published version of the map, the keyframe decision, and relocalisation after LOST. It never
// writes the map: a frame it marks as a keyframe is handed to the map's SlamMapper by the
// caller (SlamSession in-process; the daemon's Slam stream), so several cameras can track in
// one map that one mapper grows.
//
//   - Bootstrap: with no map yet, the first frame with enough valid depth to build one
//     (BootstrapDepth) is keyframe 0 at the initial pose (the frame's prior, else
//     SlamTrackerOptions::initial_pose, else the identity). Frames before it are WAITING.
//   - Tracking: constant-velocity prediction, or the caller's prior (e.g. a headset's VIO).
//   - Tracking: the map-free odometry's pose starts the map tracker; the two are fused
//     (core/slam/pose_fusion.h), which says how sure the pose is.
//   - Keyframes: only frames whose pose is sure (tracked OK, or carried by the odometry
//     through a view the map does not cover yet), by the policy (core/slam/keyframe_policy.h)
//     against every keyframe the map has accepted.
//   - Relocalisation (docs/SLAM.md, "Relocalisation"): every keyframe carries ORB features
//     (core/relocalisation/frame_features.h; SlamFrameResult::features, kept by the
//     coordinator). After a LOST frame (or from the first frame of a camera joining a map it
//     did not bootstrap), and on a frame the map contradicts although the odometry is sure
//     (a kidnap the odometry followed), the frame's features are matched against the most
//     similar keyframes and RANSAC PnP gives a pose from anywhere in the map; the dense
//     tracker verifies and refines it (on a checked frame only when that pose is elsewhere).
//     A LOST frame spends at most relocalisation_attempts_per_frame dense attempts: the
//     features' pose first, when they find one, then the poses near where the camera was (the
//     prior, the motion model's prediction, the last good pose, the nearest keyframes), the
//     next LOST frame taking up where this one stopped. An attempt that tracks OK, stays near
//     its start and passes a check at the sensor's noise is RELOCALISED. Until then frames are
//     LOST with the prediction, never an unconverged estimate; the work per frame is bounded.
//   - Before the map's first version is out (keyframe 0 still integrating), the odometry
//     carries the pose from frame to frame (DEGRADED, never a keyframe): no frame waits for it.
//   - Map segments (docs/SLAM.md, "Map segments"): a camera whose relocalisation failed on
//     new_segment_after_lost_frames frames that had depth to map (it left the map and the
//     odometry lost it too: a covered lens, a jump into space the map never saw) starts a new
//     segment: a map of its own, in a frame of its own, whose keyframe 0 is the frame. So does
//     a camera whose poses followed, for new_segment_after_unconfirmed_frames frames, from a
//     map pose the features never confirmed (frames that may not map). In a
//     segment, every segment_join_interval frames the frame's features are matched against
//     the main map's keyframes; a place found there and verified densely in the main map joins
//     the segment to it (SlamFrameResult::main_T_segment; the coordinator moves the segment's
//     keyframes into the main map) and the camera goes on in the main map.
//
// Threads: one caller at a time.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/odometry/odometry_pyramid.h"
#include "core/odometry/rgbd_odometry.h"
#include "core/relocalisation/feature_relocaliser.h"
#include "core/relocalisation/frame_features.h"
#include "core/slam/keyframe_policy.h"
#include "core/slam/pose_fusion.h"
#include "core/slam/slam_correction.h"
#include "core/slam/slam_state.h"
#include "core/slam/unconfirmed_motion.h"
#include "core/tracking/tracker.h"

namespace plx {


// The least valid depth a frame needs to bootstrap a map: pixels with depth in (0, max_depth]
// (the tracker's and the mapper's range), at least kSlamBootstrapMinDepthFraction of the frame
// and at least kSlamBootstrapMinDepthPixels.
//   - 30 %: keyframe 0's map is all the next frames track against. The tracker calls a frame
//     DEGRADED when fewer than 30 % of its rays hit the map (TrackerOptions::
//     degraded_valid_fraction, LOST below 10 %), and only frames tracked OK become keyframes:
//     after a keyframe 0 that saw less than that, a frame with full depth from the same place
//     is DEGRADED, adds no keyframe, and the map never grows past keyframe 0 (the camera is
//     LOST as soon as it moves off it). A depth camera's first frames and a covered lens have
//     ~0 %; real frames with holes (glass, black or shiny surfaces, walls out of range) keep
//     well above 30 %, so they are not refused.
//   - 256 pixels: on tiny frames 30 % is a few dozen pixels, too few to map more than a brick
//     or two, or for the tracker's robust noise scale (estimated from the spread of the
//     residuals) to mean anything. It is below 30 % of any frame from 854 pixels up (40x30 is
//     1200), so it only matters for thumbnails.
inline constexpr double kSlamBootstrapMinDepthFraction = 0.30;
inline constexpr int64_t kSlamBootstrapMinDepthPixels = 256;

struct BootstrapDepth {
  int64_t valid = 0;   // pixels with depth in (0, max_depth]
  int64_t needed = 0;  // the minimum above for the frame's size
  bool enough() const { return valid >= needed; }
};
BootstrapDepth CountBootstrapDepth(const DepthImage& depth, float max_depth);

struct SlamTrackerOptions {
  TrackerOptions tracker;
  KeyframePolicy keyframes;
  // Keyframe poses tried besides the last good pose when relocalising.
  int relocalisation_keyframes = 4;
  // An attempt that ends further than this from its starting pose is a false match.
  double relocalisation_radius_m = 0.25;
  // Dense attempts (each a map tracking run) per LOST frame, the features' pose included: the
  // rest of the list waits for the next LOST frame, so no frame pays for all of it.
  int relocalisation_attempts_per_frame = 1;
  // Relocalisation by keyframe features (and features on every keyframe). Off: only the
  // attempts near the last good pose.
  bool feature_relocalisation = true;
  FrameFeatureOptions features;
  FeatureRelocaliserOptions feature_relocaliser;
  // Where the camera starts (world_T_camera); the first frame's prior wins, else the identity.
  std::optional<SE3> initial_pose;
  // Depth beyond this does not count towards the bootstrap minimum (BootstrapDepth): the
  // nearer of the tracker's and the mapper's ranges (SplitSlamOptions).
  float bootstrap_max_depth = 10.0f;
  // The map-free odometry (core/odometry/rgbd_odometry.h) gives the map tracker its start and
  // carries the pose where the map cannot (core/slam/pose_fusion.h). Off: the map tracker
  // alone from the constant-velocity prediction (the behaviour before the odometry existed).
  bool odometry = true;
  // The keyframes a camera may leave waiting for integration (SlamGateOptions, the same
  // bound): a frame that would be a keyframe while that many wait is not taken ("keyframe
  // deferred"), so handing a keyframe over never makes the caller wait for mapping; a later
  // frame takes it once mapping has caught up (the policy's rules still hold for it). 0: every
  // keyframe is taken, and the caller waits for its integration (lock-step, or a caller that
  // wants the map to have each keyframe before the next frame).
  int max_pending_keyframes = 0;
  // A keyframe deferred on this many frames in a row is taken anyway, and the caller then
  // waits for mapping (the keyframes waiting exceed max_pending_keyframes by it). Without the
  // bound, a camera replayed faster than a starved mapper (a loaded CPU; mapping runs at lower
  // priority) tracks on the odometry into space no keyframe maps for as long as it outruns
  // mapping, which can be the whole run. 30 is a second at 30 frames/s. 0: no bound.
  int max_deferred_frames = 30;
  // The share of tracker.iterations the map tracker runs from the odometry's pose (when the
  // odometry tracked OK): that start is within millimetres of the map's optimum where the
  // motion model's can be centimetres off, so half the coarse-to-fine schedule converges
  // (docs/BENCHMARKS.md, issue 21's speed section). At least 2 iterations (one per level).
  double odometry_start_iteration_share = 0.5;
  // The map tracker's time on a frame it starts from the odometry's pose is held to this
  // multiple of its median over the last such frames (TrackerOptions::time_budget_ms, set per
  // frame): a view that puts many samples on each ray, or a CPU shared with mapping, then
  // shortens the schedule instead of the frame. 0: the iterations alone bound it. Off in
  // lock-step runs (SplitSlamOptions): a time bound makes a run depend on the machine.
  double map_time_budget = 1.3;
  // LOST frames with enough depth to map (BootstrapDepth) after which a camera starts a new map
  // segment (0: never; the camera stays LOST until relocalised). At 30 frames/s, 10 is a third
  // of a second of relocalisation attempts against the map first.
  int new_segment_after_lost_frames = 10;
  // Frames in a row chained to a map pose the keyframes' features did not confirm
  // (ChainedToUnconfirmedPose), with enough depth to map, after which the camera starts a new
  // map segment at its pose (0: never). Such frames are never keyframes, so without a bound a
  // camera the features cannot place again (it walked where no keyframe looks) tracks on, but
  // maps nothing, for as long as that lasts. A segment maps from there and joins the main map
  // by the same verified place a confirmation needs. At 30 frames/s, 30 is a second.
  int new_segment_after_unconfirmed_frames = 30;
  // In a segment, frames between attempts to find the main map by features (each costs the
  // frame's features and a match against the main map's keyframes; a dense check when found).
  int segment_join_interval = 5;
  // A tracked frame the map contradicts pays a dense check when the features place it
  // elsewhere. After such a check fails, this many of the next frames that would pay one do
  // not (their pose stays the odometry's, DEGRADED, never a keyframe): on infinitam_teddy
  // frames 472-494 each paid 110-150 ms for checks that failed. A jump the odometry could
  // not follow is unaffected (the features look first there); one it followed with
  // confidence is found at most this many frames later.
  int skip_checks_after_failed_check = 5;
  // The share of tracker.rays that check casts (both its passes): the frame has already paid
  // its map tracking, so a check at the full count made the frame about 2.5 times the median
  // and was the whole run's tail outside a correction's rebuild (docs/BENCHMARKS.md, "A
  // bounded tracking tail"). PnP has put the start within centimetres, and the second pass
  // judges the place at the sensor's noise over every ray cast; at least 256 rays.
  double on_path_check_ray_share = 0.5;
  // How long (the frames' own clock, from keyframe 0 of the map or the segment) the odometry
  // may carry the camera while the map has no version yet; a frame after that waits for it
  // (NeedsVersion). A second covers keyframe 0's integration at 640x480 on 2 cores when frames
  // come live and bounds the odometry's drift when a replay outruns mapping: the map tracker
  // then takes over. 0: every frame after keyframe 0 waits for the version. The camera is also
  // carried only while it stays within the keyframe policy's translation and rotation of
  // keyframe 0: further on, the next keyframe is due and the map it would join must exist
  // (carried on, teddy at 3x the motion left keyframe 0's view before the first version and
  // added no keyframe for 25 frames).
  double max_seconds_without_map = 1.0;
  // A live source (SlamOptions::live_source): the odometry carries the camera until the
  // version is out, however long and far, instead of the frame waiting for it. A live camera's
  // frames keep coming meanwhile: keyframe 0's version took 1.3-1.7 s at 320x240 on 2 cores,
  // and the frame after the wait needed relocalising (docs/BENCHMARKS.md). A camera LOST
  // during the carry still waits (nothing carries it).
  bool carry_until_version = false;
  OdometryPyramidOptions odometry_pyramid;
  OdometryOptions odometry_options;
  PoseFusionOptions fusion;
};

absl::Status ValidateSlamTrackerOptions(const SlamTrackerOptions& options);

// The rays a dense check of a feature place casts on a frame whose map tracking ran already:
// on_path_check_ray_share of tracker.rays, at least 256 and at most all of them.
int OnPathCheckRays(const SlamTrackerOptions& options);

// What a camera sees of the map when it tracks a frame (SlamMapper's accessors, read once).
struct SlamMapView {
  std::shared_ptr<const PlenoxelMap> map;  // the latest published version (null: none yet)
  int64_t version = 0;
  std::vector<StampedPose> accepted_keyframes;  // for the keyframe policy
  std::vector<StampedPose> keyframe_poses;      // refined, for relocalisation
  // The keyframes' features, in the same order as keyframe_poses (null: none were extracted).
  std::vector<std::shared_ptr<const FrameFeatures>> keyframe_features;
  int pending_keyframes = 0;  // accepted, not integrated yet
  // A loop-closure rebuild of the main map runs beside its mapping (SlamCoordinator): what a
  // frame's time is measured against when the benchmarks ask what a correction costs tracking.
  bool map_rebuilding = false;
  // The map's latest loop-closure correction (null: none yet): a camera whose poses are in an
  // earlier frame moves with it before it tracks (SlamTracker::Track). The main map's only.
  std::shared_ptr<const SlamCorrection> correction;
  // The map segment the view is of (0: the main map; SlamCoordinator::View). A segment's view
  // carries the main map's (map, keyframe poses and features) to find it again.
  int segment = 0;
  std::shared_ptr<const SlamMapView> main;
  // Keyframes wait for integration: the part of the view the map does not render yet is
  // mostly what they will fill in, so it does not count towards a keyframe.
  bool mapping_behind() const { return pending_keyframes > 0; }
};

// Where a frame's tracking time went, in milliseconds (the rest is bookkeeping).
struct SlamFrameTimings {
  double odometry_ms = 0.0;        // the pyramid and the frame-to-frame alignment
  double map_ms = 0.0;             // the map tracker on the frame
  double relocalisation_ms = 0.0;  // features, PnP and dense attempts (LOST or checked frames)
  double features_ms = 0.0;        // a keyframe's features, when not extracted already
};

struct SlamFrameResult {
  int frame = 0;  // 0-based count of frames given to this camera
  double timestamp = 0.0;
  SE3 pose;       // world_T_camera; for LOST frames the prediction
  SlamState state = SlamState::kLost;
  PoseSource source = PoseSource::kPrediction;  // which estimate `pose` is
  std::string reason;  // why DEGRADED / LOST, how it relocalised, or what made a keyframe
  bool keyframe = false;        // the caller hands this frame to the mapper ...
  // ... with these (SlamCoordinator::AddKeyframe); null when feature relocalisation is off.
  std::shared_ptr<const FrameFeatures> features;
  // ... and the motion since this camera's previous keyframe that the map did not confirm
  // (core/slam/unconfirmed_motion.h; zero on other frames).
  UnconfirmedMotion unconfirmed;
  int keyframes = 0;            // keyframes accepted so far, this one included
  // The map segment `pose` is in (0: the main map; set by SlamCoordinator::Accept).
  int segment = 0;
  // The frame starts a new map segment (it is that segment's keyframe 0; its pose is in the
  // new segment's frame, where the camera was predicted to be).
  bool new_segment = false;
  // The frame joined the camera's segment to the main map: main-map_T_segment, and `pose` is
  // in the main map. The segment's earlier poses map into the main map by it.
  std::optional<SE3> main_T_segment;
  int64_t map_version = 0;      // the published version the frame was tracked against
  bool map_rebuilding = false;  // the view's: a loop-closure rebuild ran meanwhile
  // The main map's frame `pose` is in: the loop-closure corrections the camera has followed
  // (SlamCorrection::generation; 0 before any).
  int correction_generation = 0;
  // Set on the first frame tracked after a correction: the correction, and how the camera
  // moved with it (new_T_old at the camera: SlamCorrection::FrameChangeAt).
  std::shared_ptr<const SlamCorrection> correction;
  SE3 frame_change;
  // The main map's keyframe the frame was anchored to when it was tracked
  // (SlamCorrection::NearestKeyframe) and that keyframe's pose then (-1: none; frames in a
  // segment): the frame keeps its pose relative to that keyframe when later corrections move
  // it (CorrectedPoses, core/slam/map_segment_poses.h).
  int reference_keyframe = -1;
  SE3 reference_keyframe_pose;
  TrackingResult tracking;      // the map tracker's rays, iterations, residual and state
  OdometryResult odometry;      // the odometry's (points 0: not run)
  double milliseconds = 0.0;    // tracking time (SlamSession: the whole ProcessFrame)
  SlamFrameTimings timings;     // its parts
};

// Per-camera counts: frames tracked, and how many ended in each SlamState (waiting: no map
// yet and too little depth to start one).
struct SlamTrackerCounts {
  int frames = 0;
  int ok = 0, degraded = 0, lost = 0, relocalised = 0, waiting = 0;
  int segments_started = 0, segments_joined = 0;
};

class SlamTracker {
 public:
  // `backend` must outlive the tracker. Whether the camera bootstraps a map or joins one is
  // decided by the view its first frames see (Track).
  SlamTracker(const SlamTrackerOptions& options, Backend* backend);

  // Checks the frame against `k` and a prior for finiteness (InvalidArgument naming the frame).
  absl::Status CheckFrame(const RgbdFrame& frame, const PinholeIntrinsics& k,
                          const std::optional<SE3>& prior) const;

  // Tracks one frame in `view` (checked with CheckFrame first). Errors are the backend's; a
  // frame that cannot be tracked is a LOST result. Until the camera has tracked a frame, a
  // view with neither a version nor an accepted keyframe makes the frame a bootstrap
  // candidate: keyframe 0 when it has enough depth (BootstrapDepth), else WAITING (one camera
  // must bootstrap a map: the caller serialises that). While the map has no version yet, the
  // odometry carries a camera that started it (CarryWithoutMap); any other frame then is
  // FailedPrecondition, with nothing changed (hand the frame in again once a version is out;
  // NeedsVersion says so beforehand). The first frame of a camera that did not
  // bootstrap the map joins it (relocalisation from the initial pose or prior).
  // `result.keyframes` counts view.accepted_keyframes plus this one.
  absl::StatusOr<SlamFrameResult> Track(const RgbdFrame& frame, const PinholeIntrinsics& k,
                                        const std::optional<SE3>& prior,
                                        const SlamMapView& view);

  // Whether Track would refuse a frame in `view` until the map has a published version.
  bool NeedsVersion(const SlamMapView& view) const {
    return view.map == nullptr && !BootstrapCandidate(view) && !CarriesWithoutMap();
  }

  // Whether the odometry can carry the pose while the map has no version: the camera started
  // the map (or a segment), the previous frame has a pose, and it is within
  // max_seconds_without_map of keyframe 0 (or carry_until_version).
  bool CarriesWithoutMap() const {
    return started_ && !lost_ && options_.odometry && previous_ && previous_->pose &&
           (options_.carry_until_version ||
            (previous_->timestamp - carry_start_ < options_.max_seconds_without_map &&
             NearCarryStart(*previous_->pose)));
  }

  const SlamTrackerCounts& counts() const { return counts_; }
  int frames() const { return counts_.frames; }

 private:
  bool BootstrapCandidate(const SlamMapView& view) const {
    return !started_ && view.map == nullptr && view.accepted_keyframes.empty();
  }
  // Within the keyframe policy's translation and rotation of keyframe 0 (carry_origin_).
  bool NearCarryStart(const SE3& pose) const;
  // A frame before the map's first version: the odometry's pose (DEGRADED), else LOST.
  absl::StatusOr<TrackingResult> CarryWithoutMap(const OdometryPyramid& pyramid,
                                                 const RgbdFrame& frame,
                                                 const std::optional<SE3>& prior,
                                                 SlamFrameResult* out);
  // A frame that starts a new segment (new_segment_after_lost_frames LOST frames, or
  // new_segment_after_unconfirmed_frames unconfirmed ones) at result->pose: keyframe 0 there,
  // OK, `reason` why (out->source is left as the caller set it).
  void StartSegment(double timestamp, std::string reason, TrackingResult* result,
                    SlamFrameResult* out);
  // In a segment, every segment_join_interval frames: the frame's place in the main map by
  // features, verified densely there (none: not found or not verified). `reason` says how.
  absl::StatusOr<std::optional<TrackingResult>> TryJoinMain(const RgbdFrame& frame,
                                                            const PinholeIntrinsics& k,
                                                            const SlamMapView& view,
                                                            std::string* reason);
  // A bootstrap candidate: keyframe 0, or WAITING without enough depth.
  SlamFrameResult Bootstrap(const RgbdFrame& frame, const std::optional<SE3>& prior,
                            OdometryPyramid pyramid, SlamFrameResult out);
  // A relocalised pose for a LOST frame: features first, then this frame's share of the
  // attempts near the last good pose. `reason` says how it was found.
  absl::StatusOr<std::optional<TrackingResult>> Relocalise(const RgbdFrame& frame,
                                                            const PinholeIntrinsics& k,
                                                            const std::optional<SE3>& prior,
                                                            const SlamMapView& view,
                                                            std::string* reason);
  // The pose RANSAC PnP finds against the keyframes' features, not verified (none when
  // feature relocalisation is off or the features find nothing).
  absl::StatusOr<std::optional<FeatureRelocalisation>> FindByFeatures(const RgbdFrame& frame,
                                                                      const PinholeIntrinsics& k,
                                                                      const SlamMapView& view);
  // That pose, verified and refined densely (TryRelocalisationFrom in `map`, the tracked map
  // when null) with `iterations` and `rays` (0: the tracker's); `reason` says how.
  absl::StatusOr<std::optional<TrackingResult>> VerifyFeaturePose(
      const FeatureRelocalisation& found, const RgbdFrame& frame, const PinholeIntrinsics& k,
      std::string* reason, const PlenoxelMap* map = nullptr, int iterations = 0, int rays = 0);
  // Gives out a place the features found and the map verified on a tracked frame: the map
  // tracker's motion model restarts there, and `out` says `state` (OK or RELOCALISED), the map
  // as its source and `reason`. Returns `place` as the frame's result.
  TrackingResult AdoptVerifiedPlace(TrackingResult place, SlamState state, std::string reason,
                                    double timestamp, SlamFrameResult* out);
  // A dense attempt of `iterations` from `start` in `map` (the tracked map when null), casting
  // `rays` (0: the tracker's): tracks OK, ends within relocalisation_radius_m of it and explains
  // the frame at the sensor's noise.
  absl::StatusOr<std::optional<TrackingResult>> TryRelocalisationFrom(
      const SE3& start, int iterations, const RgbdFrame& frame, const PinholeIntrinsics& k,
      const PlenoxelMap* map = nullptr, int rays = 0);
  // This frame's features, extracted once (null when feature relocalisation is off).
  absl::StatusOr<std::shared_ptr<const FrameFeatures>> FeaturesOf(const RgbdFrame& frame,
                                                                   const PinholeIntrinsics& k);

  // The frame's pyramid when the odometry is on (else empty).
  absl::StatusOr<OdometryPyramid> PyramidOf(const RgbdFrame& frame,
                                            const PinholeIntrinsics& k) const;
  // The odometry's pose for `frame` against the previous frame, when that one has a pose.
  absl::StatusOr<std::optional<OdometryPose>> RunOdometry(const OdometryPyramid& pyramid,
                                                           double timestamp,
                                                           const std::optional<SE3>& prior,
                                                           OdometryResult* result) const;
  // Follows the map's loop-closure corrections up to `view`'s: the camera's poses (the
  // previous frame's, the last good one, the motion model's, keyframe 0's for carrying) move
  // with the keyframe they are anchored to; `out` records it on the frame that does.
  void FollowCorrection(const SlamMapView& view, SlamFrameResult* out);
  // Keeps `pyramid` as the next frame's reference, at `pose` (none: the frame was LOST).
  // `continues`: the pose follows from the previous frame's (not a relocalisation's jump), so
  // the motion between them is the next frame's constant-velocity guess.
  void Remember(OdometryPyramid pyramid, const std::optional<SE3>& pose, double timestamp,
                bool continues = true);

  // The previous frame, as the odometry's reference.
  struct PreviousFrame {
    OdometryPyramid pyramid;
    std::optional<SE3> pose;  // none when it was LOST
    double timestamp = 0.0;
  };

  // The map tracker's time budget for the next frame it starts from the odometry (0: none
  // yet, or map_time_budget off), and the record of a frame's time.
  double MapTimeBudgetMs() const;
  void RecordMapTime(double milliseconds);

  const SlamTrackerOptions options_;
  Backend* const backend_;
  std::optional<PreviousFrame> previous_;
  // previous-but-one_T_previous and the time between them: the odometry's constant-velocity
  // starting guess.
  std::optional<SE3> last_motion_;
  double last_motion_dt_ = 0.0;
  Tracker tracker_;
  std::shared_ptr<const PlenoxelMap> tracked_map_;  // keeps the tracker's version alive
  bool started_ = false;  // bootstrapped the map or tracked a frame in it
  bool lost_ = false;
  std::optional<SE3> last_good_pose_;
  int relocalisation_cursor_ = 0;  // the next attempt near the last good pose
  int lost_with_depth_ = 0;  // LOST frames in a row that had depth to start a segment
  // Frames in a row chained to an unconfirmed map pose that had depth to start a segment.
  int unconfirmed_with_depth_ = 0;
  int checks_to_skip_ = 0;  // skip_checks_after_failed_check, counting down
  // The map tracker's last times on frames it started from the odometry (map_time_budget).
  std::deque<double> map_times_ms_;
  // The last frame's pose was a map pose the features did not confirm, or chained to one
  // (core/slam/pose_fusion.h, ChainedToUnconfirmedPose): the next frame's needs confirming.
  bool unconfirmed_chain_ = false;
  int deferred_frames_ = 0;  // frames in a row that deferred a keyframe (max_deferred_frames)
  int frames_in_segment_ = 0;  // frames tracked since the camera started its segment
  double carry_start_ = 0.0;  // keyframe 0's timestamp (of the map or the camera's segment)
  SE3 carry_origin_;          // and its pose
  int correction_generation_ = 0;  // the main map's corrections followed (FollowCorrection)
  UnconfirmedMotion unconfirmed_;  // since the camera's last keyframe
  // The current frame's features once extracted (FeaturesOf), reset per frame.
  std::shared_ptr<const FrameFeatures> frame_features_;
  SlamTrackerCounts counts_;
};

}  // namespace plx

// Loop closure for one map (docs/SLAM.md, "Loop closure"): each keyframe, once integrated, is
// checked for a place seen long before, and a verified loop corrects every keyframe's pose by a
// pose-graph solve (core/posegraph/pose_graph.h). Runs on the mapping side (SlamCoordinator's
// step-runner), never on a tracking frame's path.
//
// A loop is accepted in four steps, each of which can only say no:
//   1. Proposal (place recognition): the keyframe's thumbnail against every keyframe at least
//      `min_keyframes_apart` keyframes and `min_seconds_apart` seconds older (a dot product of
//      1200 floats each: microseconds, a few milliseconds at thousands of keyframes; measured in
//      bench/pose_graph_bench.cc); the `candidates` most similar above `min_similarity`.
//   2. Features: ORB matches (mutual best, ratio test) and RANSAC PnP of the old keyframe's 3D
//      points in the new keyframe's pixels give old_T_new with at least `min_inliers` inliers.
//   3. Dense: the map-free RGB-D odometry aligns the two keyframes' images from that pose
//      (core/odometry/rgbd_odometry.h); it must converge (its own quality gates), agree with the
//      features' pose within `max_dense_shift_m`, and explain most of the overlap
//      (`min_depth_inlier_fraction`).
//   4. The graph: the drift the loop claims must be one the chain of keyframes between them
//      could have made (PoseGraphOptions::max_loop_innovation), and the loop must still fit
//      after the solve; otherwise it is rejected and moves nothing.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/odometry/odometry_pyramid.h"
#include "core/odometry/rgbd_odometry.h"
#include "core/posegraph/pose_graph.h"
#include "core/relocalisation/feature_relocaliser.h"
#include "core/relocalisation/frame_features.h"
#include "core/slam/unconfirmed_motion.h"

namespace plx {

struct LoopClosureOptions {
  bool enabled = true;
  // Proposals: only keyframes this far back (in keyframes and in the frames' seconds) are
  // candidates; nearer ones are the chain's own neighbours, not a loop.
  int min_keyframes_apart = 10;
  double min_seconds_apart = 3.0;
  int candidates = 3;
  float min_similarity = 0.3f;
  // Features: the relocaliser's matching, with a stricter inlier count than relocalisation
  // (a wrong loop costs more than a LOST frame).
  FeatureRelocaliserOptions matching;
  int min_inliers = 30;
  // Dense: the two keyframes aligned by the odometry.
  OdometryPyramidOptions pyramid;
  OdometryOptions odometry;
  double max_dense_shift_m = 0.10;
  double max_dense_rotation_rad = 0.10;
  double min_depth_inlier_fraction = 0.6;
  // The edges' standard deviations. Sequential edges: what tracking may drift between two
  // keyframes, a floor plus a share of the motion; loop edges: the dense alignment's.
  double sequential_sigma_m = 0.005;
  double sequential_sigma_per_m = 0.05;
  double sequential_sigma_rad = 0.003;
  double sequential_sigma_per_rad = 0.05;
  // ...plus the motion the map did not confirm (core/slam/unconfirmed_motion.h: frames carried
  // by the odometry alone, relocalised or lost), at one standard deviation per metre and
  // radian: such a stretch can be off by as much as it moved. Drift gathers there: in the
  // two-room run the error grew by 20-30 cm over odometry-carried stretches and jumps (70 % of
  // the motion on one of them) and by a few cm over metres tracked OK (docs/BENCHMARKS.md,
  // "Loop closure"), so a loop's correction should go mostly to those edges, not evenly.
  double unconfirmed_sigma_per_m = 1.0;
  double unconfirmed_sigma_per_rad = 1.0;
  double loop_sigma_m = 0.005;
  double loop_sigma_rad = 0.005;
  PoseGraphOptions graph;
  // A loop whose edge already agrees with the keyframes' poses within this many of its own
  // standard deviations (normalised residual norm over six components) confirms them. Tracking
  // against the map ties a revisit to what the first pass fused, so the chain often agrees
  // already: when every loop confirms, nothing is solved or moved, since a solve would only
  // spread the loops' own measurement noise over the keyframes (and cost a rebuild). 3.5 is
  // the 95 % point of the norm of six unit Gaussians (chi-square, 6 degrees of freedom, 12.6).
  double confirm_residual = 3.5;
  // A solve that moves no keyframe more than this is no reason to rebuild the map
  // (SlamCoordinator); its loops stay in the graph for the next solve.
  double min_correction_m = 0.01;
  double min_correction_rad = 0.01;
  // A rebuild re-maps every keyframe: a correction found fewer keyframes than this after the
  // last rebuild started waits (its loops kept) until then or the end of the run.
  int min_keyframes_between_rebuilds = 10;
};

absl::Status ValidateLoopClosureOptions(const LoopClosureOptions& options);

// A keyframe as loop closure sees it. The pointers must outlive the call.
struct LoopKeyframe {
  const FrameFeatures* features = nullptr;  // null: this keyframe takes no part
  const RgbdFrame* frame = nullptr;
  const PinholeIntrinsics* intrinsics = nullptr;
  SE3 pose;  // world_T_camera as mapping refined it
};

// A verified loop: keyframe `to` (the newer) seen from keyframe `from`.
struct LoopEdge {
  int from = 0, to = 0;
  SE3 from_T_to;
  int inliers = 0;               // PnP's
  double depth_inlier_fraction = 0.0;  // the dense alignment's
};

// What one keyframe's check found (counters for observability).
struct LoopSearch {
  int proposed = 0;  // candidates ranked above min_similarity
  int rejected = 0;  // of them, failed features or dense verification
  std::optional<LoopEdge> loop;  // the best verified one
  std::string reason;            // why the last candidate was rejected
};

// Checks keyframe `query` against the older keyframes (steps 1-3 above).
absl::StatusOr<LoopSearch> SearchLoop(int query, const std::vector<LoopKeyframe>& keyframes,
                                      const std::vector<double>& timestamps,
                                      const LoopClosureOptions& options);

// The odometry edge into one keyframe of the graph: which keyframe it comes from, how much of
// the motion between them the map did not confirm, and what the two keyframes' images say.
struct SequentialLink {
  // The same camera's previous keyframe in this map (an index below this keyframe's), so that
  // with several cameras in one map each camera's drift stays on its own chain; -1: the
  // keyframe just before it in the list (a camera's first keyframe here, whose pose the map
  // tied to the others when it was accepted, or a caller that does not know the camera).
  int from = -1;
  UnconfirmedMotion unconfirmed;
  // from_T_to as MeasureSequentialLink aligned the two keyframes; none: not measured, or they
  // could not be aligned.
  std::optional<SE3> measured;
};

// Aligns keyframe `to` to keyframe `from` as a loop is verified (steps 2-3 above: the
// features' PnP, then the dense odometry from it, with the same gates; when the features match
// too few, the dense odometry starts from the poses' relative pose): none when they do not
// pass. Tracking's relative pose between a camera's consecutive
// keyframes is wrong where tracking slipped (a jump onto an older part of the map, an
// odometry-carried stretch); this is the same motion measured from the images alone.
absl::StatusOr<std::optional<SE3>> MeasureSequentialLink(const LoopKeyframe& from,
                                                         const LoopKeyframe& to,
                                                         const LoopClosureOptions& options);

struct LoopClosureEdges {
  // Sequential edges first (edges[i - 1] into keyframe i), then the loops in the order given.
  std::vector<PoseGraphEdge> edges;
  // Sequential edges that are a measurement (SequentialLink::measured) instead of the poses'
  // relative pose: the poses disagree with it beyond confirm_residual, so a solve is due.
  int measured = 0;
};

// The pose graph over `poses` (keyframes in order): one sequential edge into each keyframe but
// the first, from links[i].from (their current relative pose, the options' sigmas, wider by
// links[i].unconfirmed; `links` empty or shorter: from the keyframe before, no doubt), then
// one edge per loop. Every keyframe is joined to keyframe 0 through earlier ones, so the graph
// is connected. A link's measurement replaces the poses' relative pose (at the loops' sigmas)
// where the two disagree by more than confirm_residual of the edge's own sigmas and the edge
// lies on a cycle (a loop closes a path through it): only a loop says whether the poses before
// the edge or after it are the wrong ones; on an edge no loop closes over (another camera's
// chain beside a loop, keyframes after the newest loop) the poses, tied to the map by
// tracking, are kept.
LoopClosureEdges LoopClosureGraph(const std::vector<SE3>& poses,
                                  const std::vector<LoopEdge>& loops,
                                  const LoopClosureOptions& options,
                                  const std::vector<SequentialLink>& links = {});

struct LoopCorrection {
  std::vector<SE3> poses;          // every keyframe's corrected pose
  std::vector<int> rejected_loops; // indices into the loops given
  double max_shift_m = 0.0;        // the largest keyframe translation the solve made
  double max_rotation_rad = 0.0;
  double solve_seconds = 0.0;
  int iterations = 0;
  // The shift is large enough to rebuild the map at the new poses (min_correction_*).
  bool significant = false;
  // Every loop agreed with the poses within confirm_residual (and no measured sequential
  // edge disagreed): nothing was solved, `poses` are the poses given.
  bool confirmed = false;
  int measured_edges = 0;  // LoopClosureEdges::measured
};

// Solves LoopClosureGraph with keyframe 0 fixed (step 4), unless every loop confirms the poses
// (confirm_residual) and no sequential edge is a measurement that disagrees with them.
// InvalidArgument for a loop or link naming a keyframe outside the graph, a link from a
// keyframe not older than its own, a negative or non-finite doubt, or a measurement that is
// not finite.
absl::StatusOr<LoopCorrection> CorrectKeyframes(const std::vector<SE3>& poses,
                                                const std::vector<LoopEdge>& loops,
                                                const LoopClosureOptions& options,
                                                const std::vector<SequentialLink>& links = {});

}  // namespace plx

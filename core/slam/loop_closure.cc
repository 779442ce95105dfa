#include "core/slam/loop_closure.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

// The odometry aligns two keyframes a loop apart: their relative pose is whatever the places
// are, not a frame-to-frame step, so its motion bounds are the loop's (the features' pose
// starts it within the basin).
OdometryOptions LoopOdometry(const OdometryOptions& given, const LoopClosureOptions& options) {
  OdometryOptions o = given;
  o.max_translation_m = 1e9;
  o.max_rotation_rad = 1e9;
  o.min_depth_inlier_fraction = std::max(o.min_depth_inlier_fraction,
                                         options.min_depth_inlier_fraction);
  return o;
}

// Standard deviations of a sequential edge that moved by `motion`, `unconfirmed` of it without
// the map's confirmation.
void SequentialSigmas(const SE3& motion, const UnconfirmedMotion& unconfirmed,
                      const LoopClosureOptions& o, PoseGraphEdge* edge) {
  const double m = motion.translation().norm();
  const double rad = Eigen::AngleAxisd(motion.rotation()).angle();
  edge->sigma_m = o.sequential_sigma_m + o.sequential_sigma_per_m * m +
                  o.unconfirmed_sigma_per_m * unconfirmed.m;
  edge->sigma_rad = o.sequential_sigma_rad + o.sequential_sigma_per_rad * rad +
                    o.unconfirmed_sigma_per_rad * unconfirmed.rad;
}

}  // namespace

absl::Status ValidateLoopClosureOptions(const LoopClosureOptions& o) {
  if (o.min_keyframes_apart < 1 || o.candidates < 1 || o.min_inliers < 4) {
    return absl::InvalidArgumentError(
        "loop closure needs min_keyframes_apart >= 1, candidates >= 1 and min_inliers >= 4");
  }
  if (!(o.min_seconds_apart >= 0.0) || !(o.max_dense_shift_m > 0.0) ||
      !(o.max_dense_rotation_rad > 0.0) || !(o.min_depth_inlier_fraction >= 0.0) ||
      !(o.min_depth_inlier_fraction <= 1.0)) {
    return absl::InvalidArgumentError("loop closure's dense gates are out of range");
  }
  for (double sigma : {o.sequential_sigma_m, o.sequential_sigma_rad, o.loop_sigma_m,
                       o.loop_sigma_rad}) {
    if (!(sigma > 0.0)) return absl::InvalidArgumentError("loop closure sigmas must be > 0");
  }
  if (!(o.confirm_residual >= 0.0)) {
    return absl::InvalidArgumentError("loop closure's confirm_residual must be >= 0");
  }
  if (!(o.sequential_sigma_per_m >= 0.0) || !(o.sequential_sigma_per_rad >= 0.0) ||
      !(o.unconfirmed_sigma_per_m >= 0.0) || !(o.unconfirmed_sigma_per_rad >= 0.0) ||
      !(o.min_correction_m >= 0.0) || !(o.min_correction_rad >= 0.0)) {
    return absl::InvalidArgumentError("loop closure's per-motion sigmas and corrections >= 0");
  }
  if (o.min_keyframes_between_rebuilds < 0) {
    return absl::InvalidArgumentError("loop closure's min_keyframes_between_rebuilds >= 0");
  }
  PLX_RETURN_IF_ERROR(ValidateFeatureRelocaliserOptions(o.matching));
  PLX_RETURN_IF_ERROR(ValidateOdometryPyramidOptions(o.pyramid));
  PLX_RETURN_IF_ERROR(ValidateOdometryOptions(o.odometry));
  return ValidatePoseGraphOptions(o.graph);
}

absl::StatusOr<LoopSearch> SearchLoop(int query, const std::vector<LoopKeyframe>& keyframes,
                                      const std::vector<double>& timestamps,
                                      const LoopClosureOptions& options) {
  if (query < 0 || query >= static_cast<int>(keyframes.size()) ||
      timestamps.size() != keyframes.size()) {
    return absl::InvalidArgumentError("loop search: query or timestamps out of range");
  }
  LoopSearch search;
  const LoopKeyframe& q = keyframes[query];
  if (q.features == nullptr || q.frame == nullptr || q.intrinsics == nullptr) return search;
  // 1. Proposals among the keyframes far enough back.
  std::vector<RelocalisationKeyframe> older;
  std::vector<int> older_index;
  for (int i = 0; i + options.min_keyframes_apart <= query; ++i) {
    const LoopKeyframe& k = keyframes[i];
    if (k.features == nullptr || k.frame == nullptr || k.intrinsics == nullptr) continue;
    if (timestamps[query] - timestamps[i] < options.min_seconds_apart) continue;
    older.push_back({k.features, SE3::Identity()});
    older_index.push_back(i);
  }
  const std::vector<int> ranked =
      RankKeyframes(*q.features, older, options.candidates, options.min_similarity);
  search.proposed = static_cast<int>(ranked.size());
  if (ranked.empty()) return search;

  FeatureRelocaliserOptions matching = options.matching;
  matching.candidate_keyframes = 1;
  matching.min_inliers = std::max(matching.min_inliers, options.min_inliers);
  const OdometryOptions odometry = LoopOdometry(options.odometry, options);
  std::optional<OdometryPyramid> query_pyramid;
  for (int r : ranked) {
    const LoopKeyframe& old = keyframes[older_index[r]];
    // 2. Features: the old keyframe's points (in its camera: pose identity) seen by the query.
    const std::optional<FeatureRelocalisation> pnp =
        RelocaliseByFeatures(*q.features, {older[r]}, *q.intrinsics, matching);
    if (!pnp) {
      ++search.rejected;
      search.reason = absl::StrFormat("keyframe %d: too few feature inliers", older_index[r]);
      continue;
    }
    // 3. Dense: the query aligned to the old keyframe from the features' pose.
    if (!query_pyramid) {
      PLX_ASSIGN_OR_RETURN(query_pyramid,
                           BuildOdometryPyramid(*q.frame, *q.intrinsics, options.pyramid));
    }
    PLX_ASSIGN_OR_RETURN(const OdometryPyramid old_pyramid,
                         BuildOdometryPyramid(*old.frame, *old.intrinsics, options.pyramid));
    if (old_pyramid.levels.size() != query_pyramid->levels.size() ||
        old_pyramid.levels[0].width != query_pyramid->levels[0].width ||
        old_pyramid.levels[0].height != query_pyramid->levels[0].height) {
      ++search.rejected;
      search.reason = absl::StrFormat("keyframe %d: another camera's image size", older_index[r]);
      continue;
    }
    PLX_ASSIGN_OR_RETURN(const OdometryResult dense,
                         EstimateOdometry(old_pyramid, *query_pyramid, pnp->pose, odometry));
    const SE3 shift = pnp->pose.Inverse() * dense.reference_T_current;
    const double shift_m = shift.translation().norm();
    const double shift_rad = RotationAngleBetween(pnp->pose, dense.reference_T_current);
    if (!dense.ok || shift_m > options.max_dense_shift_m ||
        shift_rad > options.max_dense_rotation_rad) {
      ++search.rejected;
      search.reason = absl::StrFormat(
          "keyframe %d: dense check failed (%s; %.1f cm, %.1f deg from the features' pose)",
          older_index[r], dense.ok ? "converged" : dense.reason, 100 * shift_m,
          shift_rad * 180.0 / M_PI);
      continue;
    }
    if (!search.loop || pnp->inliers > search.loop->inliers) {
      search.loop = LoopEdge{older_index[r], query, dense.reference_T_current, pnp->inliers,
                             dense.depth_inlier_fraction};
    }
  }
  return search;
}

std::vector<PoseGraphEdge> LoopClosureGraph(const std::vector<SE3>& poses,
                                            const std::vector<LoopEdge>& loops,
                                            const LoopClosureOptions& options,
                                            const std::vector<SequentialLink>& links) {
  std::vector<PoseGraphEdge> edges;
  edges.reserve(poses.size() + loops.size());
  for (size_t i = 1; i < poses.size(); ++i) {
    const SequentialLink link = i < links.size() ? links[i] : SequentialLink{};
    PoseGraphEdge edge;
    edge.from = link.from >= 0 && link.from < static_cast<int>(i) ? link.from
                                                                    : static_cast<int>(i - 1);
    edge.to = static_cast<int>(i);
    edge.from_T_to = poses[edge.from].Inverse() * poses[i];
    SequentialSigmas(edge.from_T_to, link.unconfirmed, options, &edge);
    edges.push_back(edge);
  }
  for (const LoopEdge& loop : loops) {
    PoseGraphEdge edge;
    edge.from = loop.from;
    edge.to = loop.to;
    edge.from_T_to = loop.from_T_to;
    edge.sigma_m = options.loop_sigma_m;
    edge.sigma_rad = options.loop_sigma_rad;
    edge.loop = true;
    edges.push_back(edge);
  }
  return edges;
}

absl::StatusOr<LoopCorrection> CorrectKeyframes(
    const std::vector<SE3>& poses, const std::vector<LoopEdge>& loops,
    const LoopClosureOptions& options, const std::vector<SequentialLink>& links) {
  LoopCorrection correction;
  if (poses.empty()) return correction;
  for (const LoopEdge& loop : loops) {
    if (loop.from < 0 || loop.to < 0 || loop.from >= static_cast<int>(poses.size()) ||
        loop.to >= static_cast<int>(poses.size())) {
      return absl::InvalidArgumentError(
          absl::StrFormat("loop %d-%d names a keyframe not in the graph", loop.from, loop.to));
    }
  }
  for (size_t i = 0; i < links.size(); ++i) {
    const UnconfirmedMotion& u = links[i].unconfirmed;
    if (!(u.m >= 0.0 && std::isfinite(u.m) && u.rad >= 0.0 && std::isfinite(u.rad))) {
      return absl::InvalidArgumentError("a keyframe's unconfirmed motion must be finite, >= 0");
    }
    if (links[i].from < -1 || links[i].from >= static_cast<int>(std::min(i, poses.size()))) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "keyframe %d's sequential edge comes from %d, not an older keyframe", i, links[i].from));
    }
  }
  const std::vector<PoseGraphEdge> edges = LoopClosureGraph(poses, loops, options, links);
  const int first_loop = static_cast<int>(poses.size()) - 1;
  const bool all_confirm = std::all_of(
      edges.begin() + first_loop, edges.end(), [&](const PoseGraphEdge& loop) {
        return PoseGraphEdgeResidual(poses, loop) <= options.confirm_residual;
      });
  if (all_confirm) {  // no loop, or none that says the poses are wrong: nothing to move
    correction.confirmed = !loops.empty();
    correction.poses = poses;
    return correction;
  }
  PLX_ASSIGN_OR_RETURN(PoseGraphResult solved,
                       OptimisePoseGraph(poses, edges, {0}, options.graph));
  for (int e : solved.rejected_edges) correction.rejected_loops.push_back(e - first_loop);
  for (size_t i = 0; i < poses.size(); ++i) {
    correction.max_shift_m = std::max(
        correction.max_shift_m, (solved.poses[i].translation() - poses[i].translation()).norm());
    correction.max_rotation_rad =
        std::max(correction.max_rotation_rad, RotationAngleBetween(poses[i], solved.poses[i]));
  }
  correction.poses = std::move(solved.poses);
  correction.solve_seconds = solved.solve_seconds;
  correction.iterations = solved.iterations;
  correction.significant = correction.max_shift_m > options.min_correction_m ||
                           correction.max_rotation_rad > options.min_correction_rad;
  return correction;
}

}  // namespace plx

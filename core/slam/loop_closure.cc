#include "core/slam/loop_closure.h"

#include <algorithm>
#include <cmath>
#include <numeric>
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

// Steps 2-3 of a loop for one pair: `query` seen from `old` by the features' PnP, then the
// dense odometry from that pose (from `without_features` when the features find none and it
// is given). `query_pyramid` caches the query's pyramid across pairs.
struct PairAlignment {
  std::optional<SE3> old_T_query;  // none: rejected, `reason` says why
  int inliers = 0;
  double depth_inlier_fraction = 0.0;
  std::string reason;
};
absl::StatusOr<PairAlignment> AlignPair(const LoopKeyframe& old, const LoopKeyframe& query,
                                        const std::optional<SE3>& without_features,
                                        std::optional<OdometryPyramid>* query_pyramid,
                                        const LoopClosureOptions& options) {
  PairAlignment out;
  FeatureRelocaliserOptions matching = options.matching;
  matching.candidate_keyframes = 1;
  matching.min_inliers = std::max(matching.min_inliers, options.min_inliers);
  // The old keyframe's points (in its camera: pose identity) seen by the query.
  const std::optional<FeatureRelocalisation> pnp = RelocaliseByFeatures(
      *query.features, {{old.features, SE3::Identity()}}, *query.intrinsics, matching);
  if (!pnp && !without_features) {
    out.reason = "too few feature inliers";
    return out;
  }
  const SE3 start = pnp ? pnp->pose : *without_features;
  if (!*query_pyramid) {
    PLX_ASSIGN_OR_RETURN(*query_pyramid,
                         BuildOdometryPyramid(*query.frame, *query.intrinsics, options.pyramid));
  }
  PLX_ASSIGN_OR_RETURN(const OdometryPyramid old_pyramid,
                       BuildOdometryPyramid(*old.frame, *old.intrinsics, options.pyramid));
  const OdometryPyramid& q = **query_pyramid;
  if (old_pyramid.levels.size() != q.levels.size() ||
      old_pyramid.levels[0].width != q.levels[0].width ||
      old_pyramid.levels[0].height != q.levels[0].height) {
    out.reason = "another camera's image size";
    return out;
  }
  PLX_ASSIGN_OR_RETURN(const OdometryResult dense,
                       EstimateOdometry(old_pyramid, q, start,
                                        LoopOdometry(options.odometry, options)));
  const SE3 shift = start.Inverse() * dense.reference_T_current;
  const double shift_m = shift.translation().norm();
  const double shift_rad = RotationAngleBetween(start, dense.reference_T_current);
  if (!dense.ok || shift_m > options.max_dense_shift_m ||
      shift_rad > options.max_dense_rotation_rad) {
    out.reason = absl::StrFormat(
        "dense check failed (%s; %.1f cm, %.1f deg from the %s pose)",
        dense.ok ? "converged" : dense.reason, 100 * shift_m, shift_rad * 180.0 / M_PI,
        pnp ? "features'" : "given");
    return out;
  }
  out.old_T_query = dense.reference_T_current;
  out.inliers = pnp ? pnp->inliers : 0;
  out.depth_inlier_fraction = dense.depth_inlier_fraction;
  return out;
}

// Whether edges[e] lies on a cycle of the graph over `nodes` nodes: its two ends stay joined
// without it (union-find over the other edges).
bool OnACycle(int nodes, const std::vector<PoseGraphEdge>& edges, size_t e) {
  std::vector<int> parent(nodes);
  std::iota(parent.begin(), parent.end(), 0);
  const auto root = [&parent](int n) {
    while (parent[n] != n) n = parent[n] = parent[parent[n]];
    return n;
  };
  const auto inside = [nodes](const PoseGraphEdge& edge) {
    return edge.from >= 0 && edge.to >= 0 && edge.from < nodes && edge.to < nodes;
  };
  if (!inside(edges[e])) return false;
  for (size_t k = 0; k < edges.size(); ++k) {
    if (k != e && inside(edges[k])) parent[root(edges[k].from)] = root(edges[k].to);
  }
  return root(edges[e].from) == root(edges[e].to);
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

  std::optional<OdometryPyramid> query_pyramid;
  for (int r : ranked) {
    const int old = older_index[r];
    PLX_ASSIGN_OR_RETURN(const PairAlignment aligned,
                         AlignPair(keyframes[old], q, std::nullopt, &query_pyramid, options));
    if (!aligned.old_T_query) {
      ++search.rejected;
      search.reason = absl::StrFormat("keyframe %d: %s", old, aligned.reason);
      continue;
    }
    if (!search.loop || aligned.inliers > search.loop->inliers) {
      search.loop = LoopEdge{old, query, *aligned.old_T_query, aligned.inliers,
                             aligned.depth_inlier_fraction};
    }
  }
  return search;
}

absl::StatusOr<std::optional<SE3>> MeasureSequentialLink(const LoopKeyframe& from,
                                                         const LoopKeyframe& to,
                                                         const LoopClosureOptions& options) {
  if (from.features == nullptr || from.frame == nullptr || from.intrinsics == nullptr ||
      to.features == nullptr || to.frame == nullptr || to.intrinsics == nullptr) {
    return std::optional<SE3>();
  }
  // Consecutive keyframes are near each other, and where tracking did not slip its relative
  // pose is a start inside the dense alignment's basin: a pair the features cannot match (a
  // turn that leaves too few shared keypoints) is aligned from it. Where tracking slipped by
  // more than the basin, the dense check (max_dense_shift_m from its start) refuses the pair
  // or lands near the tracked pose, which then keeps its edge.
  std::optional<OdometryPyramid> to_pyramid;
  PLX_ASSIGN_OR_RETURN(const PairAlignment aligned,
                       AlignPair(from, to, from.pose.Inverse() * to.pose, &to_pyramid, options));
  return aligned.old_T_query;
}

LoopClosureEdges LoopClosureGraph(const std::vector<SE3>& poses,
                                  const std::vector<LoopEdge>& loops,
                                  const LoopClosureOptions& options,
                                  const std::vector<SequentialLink>& links) {
  LoopClosureEdges out;
  std::vector<PoseGraphEdge>& edges = out.edges;
  edges.reserve(poses.size() + loops.size());
  static const SequentialLink kUnlinked;  // from the keyframe before, no doubt
  std::vector<PoseGraphEdge> measured(poses.size());  // [i]: into keyframe i, if it disagrees
  std::vector<bool> disagrees(poses.size(), false);
  for (size_t i = 1; i < poses.size(); ++i) {
    const SequentialLink& link = i < links.size() ? links[i] : kUnlinked;
    PoseGraphEdge edge;
    edge.from = link.from >= 0 && link.from < static_cast<int>(i) ? link.from
                                                                    : static_cast<int>(i - 1);
    edge.to = static_cast<int>(i);
    edge.from_T_to = poses[edge.from].Inverse() * poses[i];
    SequentialSigmas(edge.from_T_to, link.unconfirmed, options, &edge);
    if (link.measured) {
      measured[i] = edge;  // judged at the tracked edge's sigmas...
      measured[i].from_T_to = *link.measured;
      disagrees[i] = PoseGraphEdgeResidual(poses, measured[i]) > options.confirm_residual;
      measured[i].sigma_m = options.loop_sigma_m;  // ...and as sure as a loop's alignment
      measured[i].sigma_rad = options.loop_sigma_rad;
    }
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
  for (size_t i = 1; i < poses.size(); ++i) {
    if (disagrees[i] && OnACycle(static_cast<int>(poses.size()), edges, i - 1)) {
      edges[i - 1] = measured[i];
      ++out.measured;
    }
  }
  return out;
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
    if (links[i].measured && !links[i].measured->IsFinite()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("keyframe %d's measured sequential edge is not finite", i));
    }
    if (links[i].from < -1 || links[i].from >= static_cast<int>(std::min(i, poses.size()))) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "keyframe %d's sequential edge comes from %d, not an older keyframe", i, links[i].from));
    }
  }
  const LoopClosureEdges graph = LoopClosureGraph(poses, loops, options, links);
  const std::vector<PoseGraphEdge>& edges = graph.edges;
  correction.measured_edges = graph.measured;
  const int first_loop = static_cast<int>(poses.size()) - 1;
  const bool all_confirm = graph.measured == 0 && std::all_of(
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

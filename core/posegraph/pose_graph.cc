#include "core/posegraph/pose_graph.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>

#include <ceres/ceres.h>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// The edge residual, templated for Ceres's automatic derivatives. Parameters: node i's
// quaternion (Eigen's x, y, z, w order) and translation, then node j's.
struct RelativePoseError {
  RelativePoseError(const SE3& measured, double sigma_m, double sigma_rad)
      : q_measured(measured.rotation()),
        t_measured(measured.translation()),
        inv_sigma_m(1.0 / sigma_m),
        inv_sigma_rad(1.0 / sigma_rad) {}

  template <typename T>
  bool operator()(const T* q_i_raw, const T* t_i_raw, const T* q_j_raw, const T* t_j_raw,
                  T* residual_raw) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_i(q_i_raw), q_j(q_j_raw);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t_i(t_i_raw), t_j(t_j_raw);
    const Eigen::Quaternion<T> q_i_inv = q_i.conjugate();
    const Eigen::Quaternion<T> q_ij = q_i_inv * q_j;
    const Eigen::Matrix<T, 3, 1> t_ij = q_i_inv * (t_j - t_i);
    const Eigen::Quaternion<T> q_error = q_measured.template cast<T>().conjugate() * q_ij;
    Eigen::Map<Eigen::Matrix<T, 6, 1>> residual(residual_raw);
    residual.template head<3>() = (t_ij - t_measured.template cast<T>()) * T(inv_sigma_m);
    // 2 vec(q) is the rotation vector to first order; q and -q are one rotation, so the sign
    // of w picks the short way round.
    const T sign = q_error.w() < T(0) ? T(-1) : T(1);
    residual.template tail<3>() = q_error.vec() * (T(2) * sign * T(inv_sigma_rad));
    return true;
  }

  const Eigen::Quaterniond q_measured;
  const Eigen::Vector3d t_measured;
  const double inv_sigma_m, inv_sigma_rad;
};

struct NodeParameters {
  std::array<double, 4> q;  // x, y, z, w
  std::array<double, 3> t;
};

absl::Status ValidateGraph(int nodes, const std::vector<PoseGraphEdge>& edges,
                           const std::vector<int>& fixed) {
  if (fixed.empty()) {
    return absl::InvalidArgumentError("a pose graph needs a fixed node (the gauge)");
  }
  for (int f : fixed) {
    if (f < 0 || f >= nodes) {
      return absl::InvalidArgumentError(absl::StrCat("fixed node ", f, " is not one of ", nodes));
    }
  }
  for (size_t e = 0; e < edges.size(); ++e) {
    const PoseGraphEdge& edge = edges[e];
    if (edge.from < 0 || edge.from >= nodes || edge.to < 0 || edge.to >= nodes ||
        edge.from == edge.to) {
      return absl::InvalidArgumentError(absl::StrCat("edge ", e, " joins nodes ", edge.from,
                                                     " and ", edge.to, " of ", nodes));
    }
    if (!(edge.sigma_m > 0.0) || !(edge.sigma_rad > 0.0) || !std::isfinite(edge.sigma_m) ||
        !std::isfinite(edge.sigma_rad) || !edge.from_T_to.IsFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("edge ", e, " needs finite positive sigmas and a finite pose"));
    }
  }
  return absl::OkStatus();
}

struct SolveOutcome {
  std::vector<SE3> poses;
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
};

SolveOutcome Solve(const std::vector<SE3>& poses, const std::vector<PoseGraphEdge>& edges,
                   const std::vector<bool>& active, const std::vector<int>& fixed,
                   const PoseGraphOptions& options) {
  std::vector<NodeParameters> nodes(poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Quaterniond& q = poses[i].rotation();
    nodes[i].q = {q.x(), q.y(), q.z(), q.w()};
    nodes[i].t = {poses[i].translation().x(), poses[i].translation().y(),
                  poses[i].translation().z()};
  }
  ceres::Problem problem;
  std::vector<bool> used(poses.size(), false);
  for (size_t e = 0; e < edges.size(); ++e) {
    if (!active[e]) continue;
    const PoseGraphEdge& edge = edges[e];
    auto* cost = new ceres::AutoDiffCostFunction<RelativePoseError, 6, 4, 3, 4, 3>(
        new RelativePoseError(edge.from_T_to, edge.sigma_m, edge.sigma_rad));
    ceres::LossFunction* loss = edge.loop ? new ceres::HuberLoss(options.loop_huber) : nullptr;
    NodeParameters& a = nodes[edge.from];
    NodeParameters& b = nodes[edge.to];
    problem.AddResidualBlock(cost, loss, a.q.data(), a.t.data(), b.q.data(), b.t.data());
    used[edge.from] = used[edge.to] = true;
  }
  SolveOutcome outcome;
  for (size_t i = 0; i < nodes.size(); ++i) {
    if (!used[i]) continue;
    problem.SetManifold(nodes[i].q.data(), new ceres::EigenQuaternionManifold);
  }
  for (int f : fixed) {
    if (!used[f]) continue;
    problem.SetParameterBlockConstant(nodes[f].q.data());
    problem.SetParameterBlockConstant(nodes[f].t.data());
  }
  if (problem.NumResidualBlocks() > 0) {
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    solver.max_num_iterations = options.max_iterations;
    solver.max_solver_time_in_seconds = options.max_solve_seconds;
    solver.num_threads = 1;  // the mapping side's thread; results independent of timing
    solver.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(solver, &problem, &summary);
    outcome.iterations = static_cast<int>(summary.iterations.size());
    outcome.initial_cost = summary.initial_cost;
    outcome.final_cost = summary.final_cost;
  }
  outcome.poses.reserve(nodes.size());
  for (const NodeParameters& n : nodes) {
    outcome.poses.emplace_back(Eigen::Quaterniond(n.q[3], n.q[0], n.q[1], n.q[2]),
                               Eigen::Vector3d(n.t[0], n.t[1], n.t[2]));
  }
  return outcome;
}

}  // namespace

absl::Status ValidatePoseGraphOptions(const PoseGraphOptions& options) {
  if (options.max_iterations < 1) {
    return absl::InvalidArgumentError("pose graph max_iterations must be at least 1");
  }
  if (!(options.max_solve_seconds > 0.0)) {
    return absl::InvalidArgumentError("pose graph max_solve_seconds must be positive");
  }
  if (!(options.loop_huber > 0.0) || !(options.max_loop_residual > 0.0) ||
      !(options.max_loop_innovation > 0.0)) {
    return absl::InvalidArgumentError(
        "pose graph loop_huber, max_loop_innovation and max_loop_residual must be positive");
  }
  if (options.max_rounds < 1) {
    return absl::InvalidArgumentError("pose graph max_rounds must be at least 1");
  }
  return absl::OkStatus();
}

double PoseGraphLoopInnovation(const std::vector<SE3>& poses,
                               const std::vector<PoseGraphEdge>& edges, const PoseGraphEdge& loop) {
  const int lo = std::min(loop.from, loop.to), hi = std::max(loop.from, loop.to);
  // The sequential edge into each node of the span (lo, hi].
  std::vector<const PoseGraphEdge*> into(hi - lo, nullptr);
  for (const PoseGraphEdge& e : edges) {
    if (e.loop || e.to != e.from + 1 || e.from < lo || e.to > hi) continue;
    into[e.to - lo - 1] = &e;
  }
  // Variances accumulated along the chain, in the loop's translation (metres) and rotation: each
  // edge's own, and its rotation's error swinging the rest of the chain by its lever arm.
  double var_m = loop.sigma_m * loop.sigma_m;
  double var_rad = loop.sigma_rad * loop.sigma_rad;
  const Eigen::Vector3d end = poses[hi].translation();
  for (int k = lo + 1; k <= hi; ++k) {
    const PoseGraphEdge* e = into[k - lo - 1];
    if (e == nullptr) return std::numeric_limits<double>::infinity();  // no chain to test with
    const double lever = (end - poses[k - 1].translation()).norm();
    var_m += e->sigma_m * e->sigma_m + (e->sigma_rad * lever) * (e->sigma_rad * lever);
    var_rad += e->sigma_rad * e->sigma_rad;
  }
  PoseGraphEdge combined = loop;
  combined.sigma_m = std::sqrt(var_m);
  combined.sigma_rad = std::sqrt(var_rad);
  return PoseGraphEdgeResidual(poses, combined);
}

double PoseGraphEdgeResidual(const std::vector<SE3>& poses, const PoseGraphEdge& edge) {
  const RelativePoseError error(edge.from_T_to, edge.sigma_m, edge.sigma_rad);
  const SE3& a = poses[edge.from];
  const SE3& b = poses[edge.to];
  const Eigen::Vector4d qa = a.rotation().coeffs(), qb = b.rotation().coeffs();
  Eigen::Matrix<double, 6, 1> r;
  error(qa.data(), a.translation().data(), qb.data(), b.translation().data(), r.data());
  return r.norm();
}

absl::StatusOr<PoseGraphResult> OptimisePoseGraph(const std::vector<SE3>& poses,
                                                  const std::vector<PoseGraphEdge>& edges,
                                                  const std::vector<int>& fixed,
                                                  const PoseGraphOptions& options) {
  if (absl::Status s = ValidatePoseGraphOptions(options); !s.ok()) return s;
  if (absl::Status s = ValidateGraph(static_cast<int>(poses.size()), edges, fixed); !s.ok()) {
    return s;
  }
  for (const SE3& p : poses) {
    if (!p.IsFinite()) return absl::InvalidArgumentError("a pose graph node is not finite");
  }
  const auto start = std::chrono::steady_clock::now();
  PoseGraphResult result;
  std::vector<bool> active(edges.size(), true);
  result.innovations.assign(edges.size(), 0.0);
  for (size_t e = 0; e < edges.size(); ++e) {
    if (!edges[e].loop) continue;
    result.innovations[e] = PoseGraphLoopInnovation(poses, edges, edges[e]);
    if (result.innovations[e] > options.max_loop_innovation &&
        std::isfinite(result.innovations[e])) {
      active[e] = false;
      result.rejected_edges.push_back(static_cast<int>(e));
    }
  }
  SolveOutcome outcome;
  for (int round = 0; round < options.max_rounds; ++round) {
    // Every round starts from the poses given: a rejected loop leaves no trace.
    outcome = Solve(poses, edges, active, fixed, options);
    ++result.solves;
    result.iterations += outcome.iterations;
    int worst = -1;
    double worst_residual = options.max_loop_residual;
    for (size_t e = 0; e < edges.size(); ++e) {
      if (!active[e] || !edges[e].loop) continue;
      const double r = PoseGraphEdgeResidual(outcome.poses, edges[e]);
      if (r > worst_residual) worst = static_cast<int>(e), worst_residual = r;
    }
    if (worst < 0) break;
    active[worst] = false;
    result.rejected_edges.push_back(worst);
    if (round + 1 == options.max_rounds) {
      outcome = Solve(poses, edges, active, fixed, options);  // without the last rejected
      ++result.solves;
      result.iterations += outcome.iterations;
    }
  }
  std::sort(result.rejected_edges.begin(), result.rejected_edges.end());
  result.poses = std::move(outcome.poses);
  result.residuals.reserve(edges.size());
  for (const PoseGraphEdge& edge : edges) {
    result.residuals.push_back(PoseGraphEdgeResidual(result.poses, edge));
  }
  result.initial_cost = outcome.initial_cost;
  result.final_cost = outcome.final_cost;
  result.solve_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace plx

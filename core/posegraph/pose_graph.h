// Pose-graph optimisation of keyframe poses (docs/SLAM.md, "Loop closure"): the keyframes'
// world_T_camera are the nodes, relative poses measured between two of them the edges. The
// sequential edges say what tracking measured between neighbouring keyframes; loop edges say
// what a recognised place measured between a new keyframe and an old one. After drift the two
// disagree, and the least-squares solution spreads the disagreement over the chain.
//
// Solved with Ceres (sparse normal Cholesky, Levenberg-Marquardt): one quaternion and one
// translation per node, node 0 (or the nodes the caller fixes) held constant, the gauge. The
// residual of an edge i->j with measurement Z = i_T_j is [R_i^T (t_j - t_i) - t_Z;
// 2 vec(q_Z^-1 q_i^-1 q_j)], each part divided by its standard deviation.
//
// One wrong loop must not wreck the map. A loop edge i->j (i < j) is first compared with the
// sequential chain it spans (the edges k-1 -> k for i < k <= j, which are not loops): its
// disagreement with the poses given (the drift it claims), divided by the standard deviation
// the chain's edges add up to over that span (their rotation errors with their lever arms), is
// its innovation; above `max_loop_innovation` it claims more drift than the chain can have
// made and is rejected before the solve, so it moves nothing. The loops left get a Huber loss
// (a gross error pulls with a bounded force) and, after each solve, a loop edge that still
// disagrees by more than `max_loop_residual` standard deviations is dropped and the graph solved
// again from the poses given without it.
#pragma once

#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"

namespace plx {

struct PoseGraphEdge {
  int from = 0, to = 0;
  SE3 from_T_to;          // the measured relative pose
  double sigma_m = 0.01;  // standard deviation of each translation component (metres)
  double sigma_rad = 0.01;  // of each rotation component (radians, small-angle)
  bool loop = false;      // robust loss and the rejection test apply
};

struct PoseGraphOptions {
  int max_iterations = 50;          // Levenberg-Marquardt iterations per solve
  double max_solve_seconds = 0.05;  // wall time per solve (Ceres stops at the bound)
  // Huber's threshold on a loop edge's normalised residual (standard deviations).
  double loop_huber = 2.0;
  // A loop edge whose innovation (above) exceeds this is rejected before the solve. 4.7 is
  // the 99.9 % point of the norm of six unit Gaussians (chi-square with 6 degrees of freedom
  // at 22.5): a true loop is rejected about once in a thousand.
  double max_loop_innovation = 4.7;
  // A loop edge whose normalised residual norm exceeds this after the solve is rejected.
  double max_loop_residual = 5.0;
  // Solves at most this many times (each rejecting the worst loop edge above the bound).
  int max_rounds = 3;
};

absl::Status ValidatePoseGraphOptions(const PoseGraphOptions& options);

struct PoseGraphResult {
  std::vector<SE3> poses;            // optimised, in the nodes' order
  std::vector<int> rejected_edges;   // indices into the edges given (loop edges only), sorted
  // Every loop edge's innovation (0 for the other edges; infinity for a loop the chain does
  // not span, which the test then cannot reject).
  std::vector<double> innovations;
  // Normalised residual norm of every edge after the last solve (rejected ones included, at
  // the final poses).
  std::vector<double> residuals;
  int solves = 0;
  int iterations = 0;  // over all solves
  double solve_seconds = 0.0;
  double initial_cost = 0.0, final_cost = 0.0;  // of the last solve
};

// InvalidArgument for an edge naming a node out of range, a non-positive sigma, no fixed node,
// or a fixed node out of range.
absl::StatusOr<PoseGraphResult> OptimisePoseGraph(const std::vector<SE3>& poses,
                                                  const std::vector<PoseGraphEdge>& edges,
                                                  const std::vector<int>& fixed,
                                                  const PoseGraphOptions& options);

// The normalised residual norm of `edge` at `poses` (as the solver weighs it, without the loss).
double PoseGraphEdgeResidual(const std::vector<SE3>& poses, const PoseGraphEdge& edge);

// A loop edge's innovation against the sequential chain of `edges` at `poses` (above).
double PoseGraphLoopInnovation(const std::vector<SE3>& poses,
                               const std::vector<PoseGraphEdge>& edges, const PoseGraphEdge& loop);

}  // namespace plx

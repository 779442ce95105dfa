#include "core/posegraph/pose_graph.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace plx {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The options' solve bound is wall time (50 ms): on a loaded machine (CI runs tests two at a
// time beside builds) a solve that takes a few milliseconds alone can reach it and stop early.
// These tests check what the solve finds, so they give it time; the bound is measured in
// bench/loop_closure_bench.cc.
PoseGraphOptions Untimed() {
  PoseGraphOptions options;
  options.max_solve_seconds = 30.0;
  return options;
}

// A camera on a circle of radius 1.5 m looking inwards, `n` poses per lap.
std::vector<SE3> CirclePoses(int n, int laps = 1) {
  std::vector<SE3> poses;
  for (int i = 0; i < n * laps; ++i) {
    const double a = 2.0 * kPi * i / n;
    const Eigen::Matrix3d r =
        Eigen::AngleAxisd(a + kPi / 2.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
    poses.emplace_back(r, Eigen::Vector3d(1.5 * std::cos(a), 0.1 * std::sin(3 * a),
                                          1.5 * std::sin(a)));
  }
  return poses;
}

// Sequential edges measured with a bias (a small yaw and forward creep per edge: drift), and
// the poses chained from them.
struct Chain {
  std::vector<SE3> truth, drifted;
  std::vector<PoseGraphEdge> edges;
};
Chain DriftingChain(int n, int laps, double yaw_bias_rad, double creep_m) {
  Chain chain;
  chain.truth = CirclePoses(n, laps);
  const SE3 bias(Eigen::AngleAxisd(yaw_bias_rad, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                 Eigen::Vector3d(0.0, 0.0, creep_m));
  chain.drifted.push_back(chain.truth[0]);
  for (size_t i = 1; i < chain.truth.size(); ++i) {
    PoseGraphEdge edge;
    edge.from = static_cast<int>(i - 1);
    edge.to = static_cast<int>(i);
    edge.from_T_to = chain.truth[i - 1].Inverse() * chain.truth[i] * bias;
    chain.edges.push_back(edge);
    chain.drifted.push_back(chain.drifted.back() * edge.from_T_to);
  }
  return chain;
}

PoseGraphEdge LoopEdge(const std::vector<SE3>& truth, int from, int to) {
  PoseGraphEdge edge;
  edge.from = from;
  edge.to = to;
  edge.from_T_to = truth[from].Inverse() * truth[to];
  edge.loop = true;
  return edge;
}

double TranslationError(const SE3& a, const SE3& b) {
  return (a.translation() - b.translation()).norm();
}

TEST(PoseGraphTest, ALoopEdgeTakesOutTheDrift) {
  // Two laps of 30 keyframes; the last one sees keyframe 0's place again.
  Chain chain = DriftingChain(30, 2, 0.002, 0.002);
  const int last = static_cast<int>(chain.truth.size()) - 1;
  const double before = TranslationError(chain.drifted[last], chain.truth[last]);
  ASSERT_GT(before, 0.15);  // the drift this test is about: decimetres after two laps
  std::vector<PoseGraphEdge> edges = chain.edges;
  edges.push_back(LoopEdge(chain.truth, 0, last));
  edges.push_back(LoopEdge(chain.truth, 0, 30));  // the second lap passing the start
  absl::StatusOr<PoseGraphResult> result =
      OptimisePoseGraph(chain.drifted, edges, {0}, Untimed());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(result->rejected_edges.empty());
  const double after = TranslationError(result->poses[last], chain.truth[last]);
  // The loop edges are exact and the sequential bias is spread evenly over the chain, so the
  // end lands within the loop's share of the (small) per-edge bias.
  EXPECT_LT(after, 0.02) << "before " << before;
  EXPECT_LT(result->final_cost, result->initial_cost);
  // Keyframe 0 is the gauge: held exactly.
  EXPECT_EQ(result->poses[0].translation(), chain.drifted[0].translation());
  double worst_middle = 0.0;
  for (int i = 0; i <= last; ++i) {
    worst_middle = std::max(worst_middle, TranslationError(result->poses[i], chain.truth[i]));
  }
  EXPECT_LT(worst_middle, 0.1);  // drifted by up to `before` without the loop
}

TEST(PoseGraphTest, AWrongLoopIsRejectedAndMovesNothing) {
  // A chain without drift; a loop edge claims keyframe 40 is 1 m from where it is.
  Chain chain = DriftingChain(30, 2, 0.0, 0.0);
  std::vector<PoseGraphEdge> edges = chain.edges;
  PoseGraphEdge wrong = LoopEdge(chain.truth, 2, 40);
  wrong.from_T_to = wrong.from_T_to * SE3(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(1.0, 0.0, 0.0));
  edges.push_back(wrong);
  absl::StatusOr<PoseGraphResult> result =
      OptimisePoseGraph(chain.drifted, edges, {0}, Untimed());
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_EQ(result->rejected_edges, std::vector<int>{static_cast<int>(edges.size()) - 1});
  EXPECT_GT(result->innovations.back(), PoseGraphOptions{}.max_loop_innovation);
  for (size_t i = 0; i < chain.truth.size(); ++i) {
    EXPECT_LT(TranslationError(result->poses[i], chain.drifted[i]), 1e-6) << i;
    EXPECT_LT(RotationAngleBetween(result->poses[i], chain.drifted[i]), 1e-6) << i;
  }
  EXPECT_GT(result->residuals.back(), PoseGraphOptions{}.max_loop_residual);
}

TEST(PoseGraphTest, TheSolverAloneDropsALoopTheOtherLoopsContradict) {
  // With the innovation gate off, the post-solve test catches the wrong loop where other loops
  // hold the chain (alone in its cycle, a wrong loop can always be met by bending the chain:
  // that case is the innovation gate's). Its Huber loss keeps it from bending the chain much,
  // and it is dropped and the graph solved again without it.
  Chain chain = DriftingChain(30, 2, 0.0, 0.0);
  const int last = static_cast<int>(chain.truth.size()) - 1;
  std::vector<PoseGraphEdge> edges = chain.edges;
  edges.push_back(LoopEdge(chain.truth, 0, 30));
  edges.push_back(LoopEdge(chain.truth, 0, last));
  edges.push_back(LoopEdge(chain.truth, 15, 45));
  PoseGraphEdge wrong = LoopEdge(chain.truth, 2, 40);
  wrong.from_T_to = wrong.from_T_to * SE3(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(1.0, 0.0, 0.0));
  edges.push_back(wrong);
  PoseGraphOptions options = Untimed();
  options.max_loop_innovation = 1e9;
  absl::StatusOr<PoseGraphResult> result = OptimisePoseGraph(chain.drifted, edges, {0}, options);
  ASSERT_TRUE(result.ok()) << result.status();
  // The default gate would have stopped it before the solve.
  EXPECT_GT(result->innovations.back(), PoseGraphOptions{}.max_loop_innovation);
  ASSERT_EQ(result->rejected_edges, std::vector<int>{static_cast<int>(edges.size()) - 1});
  EXPECT_EQ(result->solves, 2);
  for (size_t i = 0; i < chain.truth.size(); ++i) {
    EXPECT_LT(TranslationError(result->poses[i], chain.drifted[i]), 1e-6) << i;
  }
}

TEST(PoseGraphTest, ARightLoopSurvivesBesideAWrongOne) {
  Chain chain = DriftingChain(30, 2, 0.002, 0.002);
  const int last = static_cast<int>(chain.truth.size()) - 1;
  std::vector<PoseGraphEdge> edges = chain.edges;
  edges.push_back(LoopEdge(chain.truth, 0, last));
  PoseGraphEdge wrong = LoopEdge(chain.truth, 10, 45);
  wrong.from_T_to = wrong.from_T_to * SE3(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(0.0, 0.0, 1.2));
  edges.push_back(wrong);
  absl::StatusOr<PoseGraphResult> result =
      OptimisePoseGraph(chain.drifted, edges, {0}, Untimed());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->rejected_edges, std::vector<int>{static_cast<int>(edges.size()) - 1});
  EXPECT_LT(TranslationError(result->poses[last], chain.truth[last]), 0.02);
}

TEST(PoseGraphTest, AConsistentEdgeHasNoResidual) {
  const std::vector<SE3> truth = CirclePoses(8);
  PoseGraphEdge edge = LoopEdge(truth, 1, 6);
  EXPECT_LT(PoseGraphEdgeResidual(truth, edge), 1e-9);
  edge.sigma_m = 0.01;
  edge.from_T_to = edge.from_T_to * SE3(Eigen::Quaterniond::Identity(),
                                        Eigen::Vector3d(0.03, 0.0, 0.04));
  // 5 cm off at 1 cm per component: 5 standard deviations.
  EXPECT_NEAR(PoseGraphEdgeResidual(truth, edge), 5.0, 1e-9);
}

TEST(PoseGraphTest, BadGraphsAreRefused) {
  const std::vector<SE3> poses = CirclePoses(4);
  PoseGraphEdge edge = LoopEdge(poses, 0, 3);
  EXPECT_EQ(OptimisePoseGraph(poses, {edge}, {}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);  // no gauge
  EXPECT_EQ(OptimisePoseGraph(poses, {edge}, {4}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  PoseGraphEdge out = edge;
  out.to = 9;
  EXPECT_EQ(OptimisePoseGraph(poses, {out}, {0}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  PoseGraphEdge self = edge;
  self.to = self.from;
  EXPECT_EQ(OptimisePoseGraph(poses, {self}, {0}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  PoseGraphEdge zero = edge;
  zero.sigma_rad = 0.0;
  EXPECT_EQ(OptimisePoseGraph(poses, {zero}, {0}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  PoseGraphOptions options;
  options.max_rounds = 0;
  EXPECT_EQ(OptimisePoseGraph(poses, {edge}, {0}, options).status().code(),
            absl::StatusCode::kInvalidArgument);
  // An edge-free graph is no error: nothing moves.
  absl::StatusOr<PoseGraphResult> empty = OptimisePoseGraph(poses, {}, {0}, {});
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(empty->poses.size(), poses.size());
}

}  // namespace
}  // namespace plx

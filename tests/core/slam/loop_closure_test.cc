// Loop closure on the synthetic room: the search (place recognition, features, dense check) on
// real rendered keyframes, the pose-graph correction with a wrong loop among the right ones, and
// the coordinator closing a two-lap loop whose keyframe poses drifted (the drift added to the
// poses the keyframes are handed in with, as drifting odometry would give them), then
// publishing the rebuilt map with a correction, whose exported mesh (as `plenox export --mesh`
// and the daemon's Export make it) lies on the room's true surfaces where the drifted
// version's did not.
#include "core/slam/loop_closure.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/export/map_export.h"
#include "core/slam/map_segment_poses.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/ply_mesh_reader.h"
#include "tests/synthetic_distance.h"

namespace plx {
namespace {

// Two laps of the circle (12 s each), a keyframe every 0.4 s, at 160x120.
constexpr double kKeyframeFps = 2.5;
constexpr int kKeyframes = 61;

// The pose graph's solve bound is wall time (50 ms): on a loaded machine (CI runs tests two at
// a time beside builds) a solve of a few milliseconds alone can reach it and stop early. These
// tests check what the solve finds, so they give it time.
LoopClosureOptions Untimed() {
  LoopClosureOptions options;
  options.graph.max_solve_seconds = 30.0;
  return options;
}

// How well an exported mesh lies on the synthetic room's analytic surfaces (world frame).
struct MeshFit {
  static constexpr double kTolerance = 0.03;  // metres: one voxel at the coordinator runs' 3 cm
  int64_t vertices = 0;
  double within = 0.0;  // fraction of the vertices within kTolerance of a true surface
  double median_m = 0.0;
};

// The exported mesh (PLY, the Export defaults) of `map` against the analytic room.
MeshFit FitOfExportedMesh(const PlenoxelMap& map, Backend& backend) {
  ExportSpec spec;
  spec.mesh = true;
  const absl::StatusOr<MapExport> file = ExportMap(spec, map, MapKeyframes(), backend);
  EXPECT_TRUE(file.ok()) << file.status();
  if (!file.ok()) return {};
  const absl::StatusOr<testing::PlyMeshFile> ply = testing::ReadPlyMesh(file->bytes);
  EXPECT_TRUE(ply.ok()) << ply.status();
  if (!ply.ok()) return {};
  const TriangleMesh& mesh = ply->mesh;
  std::vector<double> distances;
  for (int64_t v = 0; v < mesh.num_vertices(); ++v) {
    const Eigen::Vector3d p(mesh.positions[3 * v], mesh.positions[3 * v + 1],
                            mesh.positions[3 * v + 2]);
    distances.push_back(testing::DistanceToSyntheticRoom(p));
  }
  MeshFit fit;
  fit.vertices = mesh.num_vertices();
  if (distances.empty()) return fit;
  fit.within = static_cast<double>(std::count_if(distances.begin(), distances.end(),
                                                 [](double d) {
                                                   return d < MeshFit::kTolerance;
                                                 })) /
               distances.size();
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  fit.median_m = distances[distances.size() / 2];
  return fit;
}

class LoopClosureTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    SyntheticOptions o;
    o.width = 160;
    o.height = 120;
    o.fps = kKeyframeFps;
    o.num_frames = kKeyframes;
    absl::StatusOr<InMemoryDataset> d = GenerateSyntheticSequence(o);
    ASSERT_TRUE(d.ok()) << d.status();
    room_ = new InMemoryDataset(std::move(*d));
    for (int i = 0; i < kKeyframes; ++i) {
      absl::StatusOr<RgbdFrame> f = room_->LoadFrame(i);
      ASSERT_TRUE(f.ok());
      frames_->push_back(*std::move(f));
      absl::StatusOr<FrameFeatures> features =
          ExtractFrameFeatures(frames_->back(), K(), FrameFeatureOptions{});
      ASSERT_TRUE(features.ok());
      features_->push_back(std::make_shared<const FrameFeatures>(*std::move(features)));
    }
  }
  static void TearDownTestSuite() {
    delete room_;
    room_ = nullptr;
    frames_->clear();
    features_->clear();
  }
  static const PinholeIntrinsics& K() { return room_->calibration().pinhole; }
  static SE3 Truth(int i) { return *room_->ground_truth(i); }

  // The true poses with a yaw and a forward creep added to every step (DriftedPoses(0.006,
  // 0.006): a third of a degree and 6 mm per keyframe-to-keyframe step, 2.5% of the motion).
  static std::vector<SE3> DriftedPoses(double yaw_rad, double creep_m) {
    const SE3 bias(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                   Eigen::Vector3d(0.0, 0.0, creep_m));
    std::vector<SE3> poses = {Truth(0)};
    for (int i = 1; i < kKeyframes; ++i) {
      poses.push_back(poses.back() * Truth(i - 1).Inverse() * Truth(i) * bias);
    }
    return poses;
  }

  static std::vector<LoopKeyframe> Keyframes(const std::vector<SE3>& poses) {
    std::vector<LoopKeyframe> out;
    for (int i = 0; i < kKeyframes; ++i) {
      out.push_back({(*features_)[i].get(), &(*frames_)[i], &K(), poses[i]});
    }
    return out;
  }
  static std::vector<double> Timestamps() {
    std::vector<double> t;
    for (const RgbdFrame& f : *frames_) t.push_back(f.timestamp);
    return t;
  }

  // Over the first `count` keyframes.
  static double MeanTranslationError(const std::vector<SE3>& poses, int count = kKeyframes) {
    double sum = 0.0;
    for (int i = 0; i < count; ++i) {
      sum += (poses[i].translation() - Truth(i).translation()).norm();
    }
    return sum / count;
  }

  // A camera on drifting odometry that moves with every correction it sees, as
  // SlamTracker::FollowCorrection does, and hands keyframe i to the coordinator.
  struct DriftingCamera {
    std::vector<SE3> drifted;
    // The odometry's frame to the map's, from the corrections followed.
    SE3 change = SE3::Identity();
    int generation = 0;
    int segment = 0;
  };
  // The correction the camera followed before keyframe i (null when none was new).
  static std::shared_ptr<const SlamCorrection> FollowAndAccept(SlamCoordinator& coordinator,
                                                               int i, DriftingCamera* camera) {
    std::shared_ptr<const SlamCorrection> seen = coordinator.correction();
    if (seen == nullptr || seen->generation <= camera->generation) {
      seen = nullptr;
    } else {
      camera->change = seen->FrameChangeAt(camera->change * camera->drifted[i - 1]) *
                       camera->change;
      camera->generation = seen->generation;
    }
    SlamFrameResult result;
    result.keyframe = true;
    result.pose = camera->change * camera->drifted[i];
    result.features = (*features_)[i];
    result.correction_generation = camera->generation;
    EXPECT_TRUE(coordinator.Accept((*frames_)[i], K(), &result, &camera->segment).ok()) << i;
    return seen;
  }

  static InMemoryDataset* room_;
  static std::vector<RgbdFrame>* frames_;
  static std::vector<std::shared_ptr<const FrameFeatures>>* features_;
};

InMemoryDataset* LoopClosureTest::room_ = nullptr;
std::vector<RgbdFrame>* LoopClosureTest::frames_ = new std::vector<RgbdFrame>();
std::vector<std::shared_ptr<const FrameFeatures>>* LoopClosureTest::features_ =
    new std::vector<std::shared_ptr<const FrameFeatures>>();

TEST_F(LoopClosureTest, TheSecondLapFindsTheFirstAndMeasuresTheTrueRelativePose) {
  // Keyframe 30 (12 s) is where keyframe 0 was; its poses as handed in are irrelevant to the
  // measurement (the features and the dense check measure it from the images alone).
  const std::vector<SE3> drifted = DriftedPoses(0.006, 0.006);
  absl::StatusOr<LoopSearch> search =
      SearchLoop(30, Keyframes(drifted), Timestamps(), LoopClosureOptions{});
  ASSERT_TRUE(search.ok()) << search.status();
  ASSERT_TRUE(search->loop.has_value()) << search->reason;
  const LoopEdge& loop = *search->loop;
  EXPECT_EQ(loop.to, 30);
  EXPECT_LE(loop.from, 20);  // at least min_keyframes_apart back
  const SE3 truth = Truth(loop.from).Inverse() * Truth(loop.to);
  // The dense alignment's accuracy at 160x120: millimetres (a 1 cm loop edge error is 2 sigma
  // of the loop edge's 5 mm).
  EXPECT_LT((loop.from_T_to.translation() - truth.translation()).norm(), 0.01);
  EXPECT_LT(RotationAngleBetween(loop.from_T_to, truth), 0.01);
  EXPECT_GE(loop.inliers, LoopClosureOptions{}.min_inliers);
}

TEST_F(LoopClosureTest, NothingIsProposedTooSoonOrBetweenDifferentPlaces) {
  const std::vector<LoopKeyframe> keyframes = Keyframes(DriftedPoses(0.0, 0.0));
  // Keyframe 9 has nothing min_keyframes_apart (10) back.
  absl::StatusOr<LoopSearch> early = SearchLoop(9, keyframes, Timestamps(), {});
  ASSERT_TRUE(early.ok());
  EXPECT_EQ(early->proposed, 0);
  EXPECT_FALSE(early->loop);
  // Half a lap on (keyframe 15 looks at the walls keyframe 0 had behind it) nothing older
  // than 10 keyframes shows the same place.
  absl::StatusOr<LoopSearch> across = SearchLoop(15, keyframes, Timestamps(), {});
  ASSERT_TRUE(across.ok());
  EXPECT_FALSE(across->loop) << "a loop to keyframe " << across->loop->from;
}

TEST_F(LoopClosureTest, AWrongLoopAmongRightOnesIsRejectedAndTheRightOnesCorrect) {
  const std::vector<SE3> drifted = DriftedPoses(0.006, 0.006);
  std::vector<LoopEdge> loops;
  for (int q : {30, 40, 50, 60}) {
    loops.push_back({q - 30, q, Truth(q - 30).Inverse() * Truth(q)});
  }
  LoopEdge wrong{5, 45, Truth(5).Inverse() * Truth(45)};  // 45 is not where 5 was: 1.4 m off
  wrong.from_T_to = wrong.from_T_to * SE3(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(0.0, 0.0, 1.0));
  loops.push_back(wrong);
  absl::StatusOr<LoopCorrection> c = CorrectKeyframes(drifted, loops, Untimed());
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->rejected_loops, std::vector<int>{4});
  EXPECT_TRUE(c->significant);
  const double before = MeanTranslationError(drifted);
  const double after = MeanTranslationError(c->poses);
  EXPECT_GT(before, 0.1);
  // Not to millimetres: the creep of a whole lap sums to nearly nothing around the circle, so
  // no loop sees that it made the first lap's circle wider (a few centimetres).
  EXPECT_LT(after, before / 3.0);

  // The wrong loop alone: rejected, nothing moves.
  absl::StatusOr<LoopCorrection> alone = CorrectKeyframes(drifted, {wrong}, Untimed());
  ASSERT_TRUE(alone.ok());
  EXPECT_EQ(alone->rejected_loops, std::vector<int>{0});
  EXPECT_FALSE(alone->significant);
  EXPECT_LT(alone->max_shift_m, 1e-9);
}

TEST_F(LoopClosureTest, ACorrectionGoesToTheEdgeTheMapDidNotConfirm) {
  // The second lap tracked well but for one stretch carried by the odometry alone into
  // keyframe 35, which slid 20 cm sideways (the two-room run's shape: drift gathered where the
  // map could not confirm the pose). Loops after it measure the truth.
  constexpr int kJump = 35;
  std::vector<SE3> tracked;
  const SE3 slide(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.2, 0.0, 0.0));
  for (int i = 0; i < kKeyframes; ++i) tracked.push_back(i < kJump ? Truth(i) : slide * Truth(i));
  std::vector<LoopEdge> loops;
  for (int q : {40, 50, 60}) loops.push_back({q - 30, q, Truth(q - 30).Inverse() * Truth(q)});
  // Without knowing where: the 20 cm spread over every edge the loops span.
  absl::StatusOr<LoopCorrection> even = CorrectKeyframes(tracked, loops, Untimed());
  ASSERT_TRUE(even.ok()) << even.status();
  // Told which motion the map did not confirm (the whole step into keyframe 35).
  std::vector<SequentialLink> links(kKeyframes);
  links[kJump].unconfirmed.Add(Truth(kJump - 1), Truth(kJump));
  absl::StatusOr<LoopCorrection> told = CorrectKeyframes(tracked, loops, Untimed(), links);
  ASSERT_TRUE(told.ok()) << told.status();
  EXPECT_TRUE(told->rejected_loops.empty());
  const double before = MeanTranslationError(tracked);
  const double spread = MeanTranslationError(even->poses);
  const double placed = MeanTranslationError(told->poses);
  EXPECT_GT(before, 0.05);
  EXPECT_LT(placed, spread / 3.0) << "before " << before << " spread " << spread;
  EXPECT_LT(placed, 0.01) << "before " << before << " spread " << spread;
  // A doubt that is not a number is refused, not solved with.
  links[3].unconfirmed.m = -1.0;
  EXPECT_FALSE(CorrectKeyframes(tracked, loops, Untimed(), links).ok());
}

TEST_F(LoopClosureTest, AJumpBackOntoTheOldMapIsMeasuredAndTheDriftBeforeItCorrected) {
  // The two-room run's shape: a stretch carried by the odometry alone (keyframes 20-34) slid
  // sideways, 20 cm by its end; then tracking found the first lap's map again and the pose
  // jumped back onto it (35 on exact). Loops from the start to after the jump agree with the
  // poses, so they say nothing is wrong; the edge across the jump holds the 20 cm.
  constexpr int kJump = 35;
  std::vector<SE3> tracked;
  for (int i = 0; i < kKeyframes; ++i) {
    const double slide = i >= 20 && i < kJump ? 0.2 * (i - 19) / 15.0 : 0.0;
    tracked.push_back(SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(slide, 0.0, 0.0)) *
                      Truth(i));
  }
  std::vector<LoopEdge> loops;
  for (int q : {36, 40, 45}) loops.push_back({q - 36, q, Truth(q - 36).Inverse() * Truth(q)});
  // Every edge measured (the truth but the jump's, which the images measure here from the
  // tracked poses, 20 cm wrong), the stretch flagged as unconfirmed motion.
  std::vector<SequentialLink> links(kKeyframes);
  for (int i = 1; i < kKeyframes; ++i) {
    links[i].measured = Truth(i - 1).Inverse() * Truth(i);
    if (i >= 20 && i < kJump) links[i].unconfirmed.Add(Truth(i - 1), Truth(i));
  }
  const std::vector<LoopKeyframe> keyframes = Keyframes(tracked);
  absl::StatusOr<std::optional<SE3>> jump =
      MeasureSequentialLink(keyframes[kJump - 1], keyframes[kJump], LoopClosureOptions{});
  ASSERT_TRUE(jump.ok()) << jump.status();
  ASSERT_TRUE(jump->has_value());
  const SE3 truth = Truth(kJump - 1).Inverse() * Truth(kJump);
  // The dense alignment's millimetres, as a loop's (TheSecondLapFinds...).
  EXPECT_LT(((*jump)->translation() - truth.translation()).norm(), 0.01);
  EXPECT_LT(RotationAngleBetween(**jump, truth), 0.01);
  links[kJump].measured = *jump;

  absl::StatusOr<LoopCorrection> unmeasured = CorrectKeyframes(tracked, loops, Untimed());
  ASSERT_TRUE(unmeasured.ok()) << unmeasured.status();
  EXPECT_TRUE(unmeasured->confirmed);
  absl::StatusOr<LoopCorrection> c = CorrectKeyframes(tracked, loops, Untimed(), links);
  ASSERT_TRUE(c.ok()) << c.status();
  // Only the jump's measurement disagrees with tracking beyond its doubt: the stretch's edges
  // moved within what unconfirmed motion allows, the others agree.
  EXPECT_EQ(c->measured_edges, 1);
  EXPECT_FALSE(c->confirmed);
  EXPECT_TRUE(c->rejected_loops.empty());
  const double before = MeanTranslationError(tracked);
  EXPECT_GT(before, 0.02);
  EXPECT_LT(MeanTranslationError(c->poses), before / 5.0) << "before " << before;
  for (int i = kJump; i < kKeyframes; ++i) {  // what tracking put on the old map stays there
    EXPECT_LT((c->poses[i].translation() - Truth(i).translation()).norm(), 0.005) << i;
  }
  // No loop spans the jump: which side is wrong is unknown, and the poses stay.
  const std::vector<LoopEdge> early = {{0, 12, Truth(0).Inverse() * Truth(12)}};
  absl::StatusOr<LoopCorrection> unspanned = CorrectKeyframes(tracked, early, Untimed(), links);
  ASSERT_TRUE(unspanned.ok()) << unspanned.status();
  EXPECT_EQ(unspanned->measured_edges, 0);
  EXPECT_EQ(unspanned->max_shift_m, 0.0);
  // A measurement that is not a pose is refused.
  links[3].measured = SE3(Eigen::Quaterniond::Identity(),
                          Eigen::Vector3d(std::nan(""), 0.0, 0.0));
  EXPECT_FALSE(CorrectKeyframes(tracked, loops, Untimed(), links).ok());
}

TEST_F(LoopClosureTest, ALoopOnOneCameraCorrectsItsChainAndLeavesTheOtherCamera) {
  // Two cameras in one map, their keyframes accepted in turn (A0 B0 A1 B1 ...): A drifts, B
  // (a rig's second camera, 30 cm beside A's path) tracks exactly and closes no loop. Loops on
  // A's second lap measure A's truth.
  const std::vector<SE3> drifted = DriftedPoses(0.006, 0.006);
  const SE3 beside(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.3, 0.0, 0.0));
  std::vector<SE3> poses, truth;
  std::vector<SequentialLink> chains;
  for (int i = 0; i < kKeyframes; ++i) {
    poses.push_back(drifted[i]);
    truth.push_back(Truth(i));
    chains.push_back({i > 0 ? 2 * (i - 1) : -1, {}, {}});
    poses.push_back(Truth(i) * beside);
    truth.push_back(Truth(i) * beside);
    chains.push_back({i > 0 ? 2 * (i - 1) + 1 : -1, {}, {}});  // B0's: from A0, the one before
  }
  std::vector<LoopEdge> loops;
  for (int q : {40, 50, 60}) {
    loops.push_back({2 * (q - 30), 2 * q, Truth(q - 30).Inverse() * Truth(q)});
  }
  auto mean_error = [&](const std::vector<SE3>& p, int camera) {
    double sum = 0.0;
    for (int i = camera; i < 2 * kKeyframes; i += 2) {
      sum += (p[i].translation() - truth[i].translation()).norm();
    }
    return sum / kKeyframes;
  };
  absl::StatusOr<LoopCorrection> chained = CorrectKeyframes(poses, loops, Untimed(), chains);
  ASSERT_TRUE(chained.ok()) << chained.status();
  // The same keyframes linked in the order accepted (what a caller that names no camera gets).
  absl::StatusOr<LoopCorrection> interleaved = CorrectKeyframes(poses, loops, Untimed());
  ASSERT_TRUE(interleaved.ok()) << interleaved.status();
  // A alone, with the same loops: what A's chain should get.
  std::vector<LoopEdge> own_loops;
  for (int q : {40, 50, 60}) own_loops.push_back({q - 30, q, Truth(q - 30).Inverse() * Truth(q)});
  absl::StatusOr<LoopCorrection> alone = CorrectKeyframes(drifted, own_loops, Untimed());
  ASSERT_TRUE(alone.ok()) << alone.status();
  const double a_before = mean_error(poses, 0);
  const double a_alone = MeanTranslationError(alone->poses);
  EXPECT_LT(a_alone, a_before / 2.0);
  EXPECT_NEAR(mean_error(chained->poses, 0), a_alone, 1e-3) << "drifted by " << a_before;
  // B's edges agree with B's poses: only B0's link to A0 (fixed) could move it, so it stays.
  EXPECT_LT(mean_error(chained->poses, 1), 1e-3);
  // Interleaved, every B keyframe sits between two of A's and follows A's correction.
  EXPECT_GT(mean_error(interleaved->poses, 1), 0.01);
  // A measurement on B's chain that disagrees with B's poses by 10 cm, between two keyframes
  // that lie between a loop's two: no loop closes over B's chain, so it cannot say whether B's
  // keyframes before it or after it are wrong, and B stays.
  std::vector<SequentialLink> measured_b = chains;
  measured_b[2 * 45 + 1].measured =
      poses[2 * 44 + 1].Inverse() * poses[2 * 45 + 1] *
      SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0.0, 0.0));
  absl::StatusOr<LoopCorrection> b_kept = CorrectKeyframes(poses, loops, Untimed(), measured_b);
  ASSERT_TRUE(b_kept.ok()) << b_kept.status();
  EXPECT_EQ(b_kept->measured_edges, 0);
  EXPECT_LT(mean_error(b_kept->poses, 1), 1e-3);
  // A link from a keyframe that is not older is refused.
  chains[5].from = 5;
  EXPECT_FALSE(CorrectKeyframes(poses, loops, Untimed(), chains).ok());
  chains[5].from = 2 * kKeyframes;
  EXPECT_FALSE(CorrectKeyframes(poses, loops, Untimed(), chains).ok());
}

TEST_F(LoopClosureTest, LoopsThatAgreeWithThePosesWithinTheirNoiseMoveNothing) {
  // Tracking against the map already put the second lap where the first one was: the loops
  // (measured to within a few millimetres) confirm the poses, and a solve would only move
  // keyframes by their noise.
  const std::vector<SE3> tracked = DriftedPoses(0.0, 0.0);
  std::vector<LoopEdge> loops;
  const SE3 noise(Eigen::Quaterniond(Eigen::AngleAxisd(0.004, Eigen::Vector3d::UnitY())),
                  Eigen::Vector3d(0.006, -0.004, 0.003));  // about 2 sigma of the loop edge
  for (int q : {30, 40, 50}) {
    loops.push_back({q - 30, q, Truth(q - 30).Inverse() * Truth(q) * noise});
  }
  absl::StatusOr<LoopCorrection> c = CorrectKeyframes(tracked, loops, Untimed());
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_TRUE(c->confirmed);
  EXPECT_FALSE(c->significant);
  EXPECT_TRUE(c->rejected_loops.empty());
  EXPECT_EQ(c->max_shift_m, 0.0);
  for (size_t i = 0; i < tracked.size(); ++i) {
    EXPECT_EQ(c->poses[i].translation(), tracked[i].translation()) << i;
  }
  // Three times that noise is beyond what the loop edge's own sigma explains: solved.
  const SE3 more(Eigen::Quaterniond(Eigen::AngleAxisd(0.012, Eigen::Vector3d::UnitY())),
                 Eigen::Vector3d(0.018, -0.012, 0.009));
  loops.back().from_T_to = Truth(20).Inverse() * Truth(50) * more;
  absl::StatusOr<LoopCorrection> solved = CorrectKeyframes(tracked, loops, Untimed());
  ASSERT_TRUE(solved.ok()) << solved.status();
  EXPECT_FALSE(solved->confirmed);
  EXPECT_GT(solved->max_shift_m, 0.0);
}

TEST_F(LoopClosureTest, TheCoordinatorClosesTheLoopAndPublishesTheCorrectedMap) {
  SlamOptions o = DefaultSlamOptions();
  o.deterministic = true;
  o.mapping.mapper = MapperOptionsForVoxelSize(0.03f);
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.batch_size = 1024;
  o.mapping.iterations_per_keyframe = 5;
  o.refinement.window = 0;  // the poses handed in are what the graph corrects
  const SlamSplitOptions split = SplitSlamOptions(o);
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  SlamCoordinator coordinator(split.mapper, split.gate);
  ASSERT_TRUE(coordinator.StartMapper(backend.get()).ok());
  DriftingCamera camera{DriftedPoses(0.006, 0.006)};
  const std::vector<SE3>& drifted = camera.drifted;
  SlamMapVersion drifted_map;  // the newest version published before the first correction
  bool seen_rebuilding = false;  // a camera's view said a rebuild runs
  auto step_until_out_of_work = [&](SlamStepMode mode) {
    for (int steps = 0; steps < 100000; ++steps) {
      absl::StatusOr<SlamStepResult> r = coordinator.Step(mode);
      ASSERT_TRUE(r.ok()) << r.status();
      seen_rebuilding = seen_rebuilding || coordinator.View().map_rebuilding;
      if (r->out_of_work) return;
    }
    FAIL() << "the coordinator never ran out of work";
  };
  for (int i = 0; i < kKeyframes; ++i) {
    FollowAndAccept(coordinator, i, &camera);
    step_until_out_of_work(SlamStepMode::kMap);
    if (coordinator.correction() == nullptr) drifted_map = coordinator.latest();
  }
  step_until_out_of_work(SlamStepMode::kFinish);  // a correction waiting for its turn comes now
  const std::shared_ptr<const SlamCorrection> correction = coordinator.correction();
  ASSERT_NE(correction, nullptr);
  const SlamMapperProgress p = coordinator.progress();
  std::printf("%d loops accepted, %d corrections, %d links measured, %d used by the last solve "
              "(%.1f ms)\n",
              p.loops.accepted, p.loops.corrections, p.loops.links_measured,
              p.loops.last_measured_edges, p.loops.last_solve_ms);
  EXPECT_GE(p.loops.accepted, 1);
  EXPECT_GE(p.loops.corrections, 1);
  // Each keyframe's edge from the one before was measured from the images (60 edges; a pair
  // the checks refuse goes unmeasured), and none replaced tracking's: the drift per keyframe
  // is within the sequential edge's doubt.
  EXPECT_GE(p.loops.links_measured, kKeyframes * 3 / 4);
  EXPECT_LE(p.loops.links_measured, kKeyframes - 1);
  EXPECT_EQ(p.loops.last_measured_edges, 0);
  EXPECT_EQ(correction->generation, p.loops.corrections);
  ASSERT_NE(drifted_map.map, nullptr);
  EXPECT_GT(correction->map_version, drifted_map.version);
  EXPECT_EQ(coordinator.latest().version, p.map_version);
  EXPECT_GE(coordinator.latest().version, correction->map_version);
  EXPECT_EQ(coordinator.View().correction, correction);
  // Every correction is kept, oldest first: a camera whose last frame was tracked before them
  // all gets each (the daemon's done message), one that followed the last gets none.
  const std::vector<std::shared_ptr<const SlamCorrection>> kept = coordinator.CorrectionsAfter(0);
  ASSERT_EQ(kept.size(), static_cast<size_t>(p.loops.corrections));
  for (size_t g = 0; g < kept.size(); ++g) EXPECT_EQ(kept[g]->generation, static_cast<int>(g + 1));
  EXPECT_EQ(kept.back(), correction);
  EXPECT_TRUE(coordinator.CorrectionsAfter(correction->generation).empty());
  EXPECT_TRUE(seen_rebuilding);
  EXPECT_FALSE(coordinator.View().map_rebuilding);
  // Refinement's window is off here: only the rebuild's alignment of every keyframe moved any.
  EXPECT_GT(p.refined_keyframes, 0);

  std::vector<SE3> corrected;
  for (const StampedPose& kf : coordinator.keyframe_poses()) corrected.push_back(kf.pose);
  ASSERT_EQ(corrected.size(), static_cast<size_t>(kKeyframes));
  const double before = MeanTranslationError(drifted);
  const double after = MeanTranslationError(corrected);
  EXPECT_LT(after, before / 3.0) << "before " << before << " m, after " << after << " m, "
                                 << p.loops.accepted << " loops, " << p.loops.corrections
                                 << " corrections";
  // The last keyframe (where the drift was largest) back within centimetres.
  EXPECT_LT((corrected.back().translation() - Truth(kKeyframes - 1).translation()).norm(), 0.05);

  // Export reads whatever version is published: the mesh of the newest one is the corrected
  // surface, not the drifted version's doubled walls, in the world frame keyframe 0 anchors.
  const SlamMapVersion corrected_map = coordinator.latest();
  ASSERT_NE(corrected_map.map, nullptr);
  const MeshFit mesh_before = FitOfExportedMesh(*drifted_map.map, *backend);
  const MeshFit mesh_after = FitOfExportedMesh(*corrected_map.map, *backend);
  std::printf("version %ld (drifted): %ld vertices, %.3f within %.0f cm, median %.1f mm; "
              "version %ld (corrected): %ld vertices, %.3f, median %.1f mm\n",
              static_cast<long>(drifted_map.version), static_cast<long>(mesh_before.vertices),
              mesh_before.within, 100 * MeshFit::kTolerance, 1000 * mesh_before.median_m,
              static_cast<long>(corrected_map.version), static_cast<long>(mesh_after.vertices),
              mesh_after.within, 1000 * mesh_after.median_m);
  ASSERT_GT(mesh_after.vertices, 1000);
  // On the room's surfaces within what 5 iterations a keyframe and the correction's residual
  // pose error leave (measured: 0.576 of the vertices within 3 cm, median 27.3 mm; lock-step
  // runs are alike however loaded the machine) ...
  EXPECT_GT(mesh_after.within, 0.5);
  EXPECT_LT(mesh_after.median_m, MeshFit::kTolerance);
  // ... and they are the corrected ones: the drifted version's are not (0.342, median 60 mm).
  EXPECT_GT(mesh_after.within, mesh_before.within + 0.15);
  EXPECT_LT(mesh_after.median_m, 0.6 * mesh_before.median_m);
}

TEST_F(LoopClosureTest, ACorrectionWithinTheInPlaceLimitMovesTheRunningMapWithoutARebuild) {
  SlamOptions o = DefaultSlamOptions();
  o.deterministic = true;
  o.mapping.mapper = MapperOptionsForVoxelSize(0.03f);
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.batch_size = 1024;
  o.mapping.iterations_per_keyframe = 2;
  o.refinement.window = 0;
  SlamSplitOptions split = SplitSlamOptions(o);
  split.mapper.in_place_max_shift_m = 1.0;  // every correction of this drift is applied in place
  std::unique_ptr<Backend> backend = MakeCpuBackend(1);
  SlamCoordinator coordinator(split.mapper, split.gate);
  ASSERT_TRUE(coordinator.StartMapper(backend.get()).ok());
  // The second lap's first 15 keyframes: enough loops to correct the first lap's drift.
  constexpr int kUsed = 46;
  DriftingCamera camera{DriftedPoses(0.006, 0.006)};
  bool seen_rebuilding = false;
  int64_t versions_seen = 0;
  for (int i = 0; i < kUsed; ++i) {
    const int64_t latest = coordinator.latest().version;
    const std::shared_ptr<const SlamCorrection> seen = FollowAndAccept(coordinator, i, &camera);
    // Published with the map version it belongs to, which readers already see.
    if (seen != nullptr) {
      EXPECT_LE(seen->map_version, latest);
    }
    for (int steps = 0;; ++steps) {
      ASSERT_LT(steps, 100000);
      absl::StatusOr<SlamStepResult> r = coordinator.Step(SlamStepMode::kMap);
      ASSERT_TRUE(r.ok()) << r.status();
      seen_rebuilding = seen_rebuilding || coordinator.View().map_rebuilding;
      EXPECT_GE(coordinator.latest().version, versions_seen);  // never back
      versions_seen = coordinator.latest().version;
      if (r->out_of_work) break;
    }
  }
  const SlamMapperProgress p = coordinator.progress();
  ASSERT_GE(p.loops.corrections, 1);
  EXPECT_EQ(p.loops.in_place, p.loops.corrections);
  EXPECT_FALSE(seen_rebuilding);
  EXPECT_EQ(p.refined_keyframes, 0);  // no rebuild, so no rebuild's alignment
  const std::shared_ptr<const SlamCorrection> correction = coordinator.correction();
  ASSERT_NE(correction, nullptr);
  EXPECT_EQ(correction->generation, p.loops.corrections);
  // The keyframes the map holds are the corrected ones: the drift of the first lap is mostly
  // gone (mean error a third or less of the drifted poses').
  std::vector<SE3> corrected;
  for (const StampedPose& kf : coordinator.keyframe_poses()) corrected.push_back(kf.pose);
  ASSERT_EQ(corrected.size(), static_cast<size_t>(kUsed));
  const double before = MeanTranslationError(camera.drifted, kUsed);
  const double after = MeanTranslationError(corrected, kUsed);
  EXPECT_LT(after, before / 3.0) << "before " << before << " m, after " << after << " m";
}

TEST(SlamCorrectionTest, APoseMovesWithItsNearestKeyframe) {
  SlamCorrection c;
  c.before = {SE3::Identity(), SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2, 0, 0))};
  const SE3 lift(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0.5, 0));
  c.after = {c.before[0], lift * c.before[1]};
  const SE3 near_second(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1.8, 0, 0));
  EXPECT_EQ(c.NearestKeyframe(near_second), 1);
  EXPECT_TRUE(c.Move(near_second).translation().isApprox(Eigen::Vector3d(1.8, 0.5, 0)));
  const SE3 near_first(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.3, 0, 0));
  EXPECT_TRUE(c.Move(near_first).translation().isApprox(near_first.translation()));
  EXPECT_EQ(SlamCorrection{}.NearestKeyframe(near_first), -1);
  // A place passed twice: the newer keyframe (the drifted chain the camera walks on from).
  c.before.push_back(SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0, 0)));
  c.after.push_back(c.before.back());
  EXPECT_EQ(c.NearestKeyframe(SE3::Identity()), 2);
}

TEST(SlamCorrectionTest, ACameraThatFollowedNoneMovesThroughEachInTurn) {
  // Two corrections after a camera's last pose: the first lifts the keyframe at 2 m, the
  // second (in the lifted frame) shifts it along x. Each frame change is taken where the
  // ones before moved the pose, so their product is both moves.
  const SE3 at(Eigen::Quaterniond::Identity(), Eigen::Vector3d(2, 0, 0));
  auto first = std::make_shared<SlamCorrection>();
  first->generation = 1;
  first->before = {SE3::Identity(), at};
  first->after = {SE3::Identity(),
                  SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0.5, 0)) * at};
  auto second = std::make_shared<SlamCorrection>();
  second->generation = 2;
  second->before = first->after;
  second->after = {SE3::Identity(),
                   SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.25, 0, 0)) *
                       first->after[1]};
  const SE3 camera(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1.8, 0, 0));
  const std::vector<SE3> changes = FrameChangesAlong({first, second}, camera);
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_TRUE((changes[0] * camera).translation().isApprox(Eigen::Vector3d(1.8, 0.5, 0)));
  EXPECT_TRUE(
      (changes[1] * changes[0] * camera).translation().isApprox(Eigen::Vector3d(2.05, 0.5, 0)));
  EXPECT_TRUE((changes[1] * changes[0] * camera)
                  .translation()
                  .isApprox(second->Move(first->Move(camera)).translation()));
  EXPECT_TRUE(FrameChangesAlong({}, camera).empty());
}

TEST(CorrectedPosesTest, AFrameKeepsItsPoseRelativeToItsKeyframe) {
  SlamFrameResult anchored;
  anchored.pose = SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1.1, 0, 0));
  anchored.reference_keyframe = 1;
  anchored.reference_keyframe_pose = SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 0));
  SlamFrameResult free;  // no keyframe to anchor to: as tracked
  free.pose = SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(5, 0, 0));
  const std::vector<StampedPose> final_keyframes = {
      {0.0, SE3::Identity()},
      {1.0, SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0.2, 0))}};
  const std::vector<StampedPose> poses = CorrectedPoses({anchored, free}, final_keyframes);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_TRUE(poses[0].pose.translation().isApprox(Eigen::Vector3d(1.1, 0.2, 0)));
  EXPECT_TRUE(poses[1].pose.translation().isApprox(Eigen::Vector3d(5, 0, 0)));
}

TEST(FollowCorrectionsTest, APoseMovesThroughTheCorrectionsAfterItsFrame) {
  const SE3 at_one(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 0));
  const SE3 lift(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0.5, 0));
  SlamCorrection first;
  first.generation = 1;
  first.before = {SE3::Identity(), at_one};
  first.after = {SE3::Identity(), lift * at_one};
  SlamFrameResult old_frame;  // tracked before the correction: moves with keyframe 1
  old_frame.pose = at_one;
  SlamFrameResult new_frame;  // tracked in the corrected frame: stays
  new_frame.pose = lift * at_one;
  new_frame.correction_generation = 1;
  SlamFrameResult lost_segment;  // a segment never joined keeps its own frame
  lost_segment.segment = 1;
  lost_segment.pose = at_one;
  const std::vector<StampedPose> poses =
      FollowCorrections({old_frame, new_frame, lost_segment}, {first});
  ASSERT_EQ(poses.size(), 3u);
  EXPECT_TRUE(poses[0].pose.translation().isApprox(Eigen::Vector3d(1, 0.5, 0)));
  EXPECT_TRUE(poses[1].pose.translation().isApprox(Eigen::Vector3d(1, 0.5, 0)));
  EXPECT_TRUE(poses[2].pose.translation().isApprox(Eigen::Vector3d(1, 0, 0)));
}

}  // namespace
}  // namespace plx

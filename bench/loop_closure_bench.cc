// plx_loop_closure_bench: loop closure on its own (docs/BENCHMARKS.md, "Loop closure").
//
//   build/bench/plx_loop_closure_bench [--width 320 --height 240 --laps 2 --iterations 30
//                                       --yaw-drift-deg 0.35 --creep-cm 0.6 --drift-from 0
//                                       --graph-only
//                                       --cases true,drift,loop,loop-rebuild,loop-seeded,
//                                               loop-unrefined]
//
// 1. The synthetic two-lap loop: keyframes every 0.4 s over `laps` laps of the room (12 s
//    each), handed to a lock-step SlamCoordinator at poses that drift (each step's true
//    motion times a yaw and a forward creep: odometry that drifts), once with loop closure
//    (small corrections applied in place), again with every correction rebuilt from nothing
//    (loop-rebuild) or from what did not move (loop-seeded), and from nothing without the
//    rebuild's refinement of every keyframe (loop-unrefined), once without
//    loop closure, and once at the true poses (the reference map). Prints per run: the last
//    keyframe's error, the keyframes' mean translation error and ATE (rigidly aligned), loops
//    accepted and false (a loop edge more than 5 cm or 2 degrees from the truth), corrections
//    published, the held-out frames' depth L1 and PSNR (frames halfway between keyframes, at
//    their true poses, and again at those poses brought into the map's frame by the keyframes'
//    rigid alignment to the truth: alignL1, apsnr), and the wall time.
// 2. Pose-graph solves at 100, 500 and 1000 keyframes (two laps of a chain drifting 3 degrees
//    and 1 % of the path per lap, a loop edge every tenth keyframe of the second lap):
//    milliseconds (median of 5), loops rejected, the end-point error before and after.
// 3. Place recognition: ranking one keyframe's thumbnail against N keyframes (microseconds).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "core/eval/trajectory_metrics.h"
#include "core/posegraph/pose_graph.h"
#include "core/relocalisation/feature_relocaliser.h"
#include "core/slam/loop_closure.h"
#include "core/slam/slam_coordinator.h"
#include "core/slam/slam_session.h"
#include "core/synthetic/synthetic_sequence.h"

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kPi = 3.14159265358979323846;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

struct Flags {
  int width = 320, height = 240, laps = 2, iterations = 30;
  double yaw_drift_deg = 0.35, creep_cm = 0.6;
  // The share of the path tracked without drift before the odometry starts drifting: with 0.5
  // the first lap is exact and only the second drifts, so a correction moves only the second
  // lap's keyframes (what a loop after a stretch of good tracking moves).
  double drift_from = 0.0;
  bool graph_only = false;
  // Which two-lap runs: true (true poses), drift (no loop closure), loop (loop closure, small
  // corrections in place), loop-rebuild (every correction rebuilt from nothing), loop-seeded
  // (every correction rebuilt from what did not move), loop-unrefined (rebuilt from nothing
  // without the rebuild's refinement of every keyframe: the first implementation).
  std::string cases = "true,drift,loop,loop-rebuild,loop-seeded,loop-unrefined";
};

plx::SE3 Bias(const Flags& f) {
  return plx::SE3(Eigen::AngleAxisd(f.yaw_drift_deg * kPi / 180.0, Eigen::Vector3d::UnitY())
                      .toRotationMatrix(),
                  Eigen::Vector3d(0.0, 0.0, f.creep_cm / 100.0));
}

struct RunResult {
  std::vector<plx::SE3> keyframes;
  plx::SlamMapperProgress progress;
  int false_loops = 0;
  plx::MapEvalResult eval;
  // The same frames at their true poses brought into the map's frame by the keyframes' rigid
  // alignment to the truth: the map's own quality, whatever frame it was built in.
  plx::MapEvalResult aligned_eval;
  double seconds = 0.0;
};

// Hands the keyframes (dataset frames `indices`) to a lock-step coordinator at `poses`, as a
// camera would: in the frame of the last correction it saw.
absl::StatusOr<RunResult> RunKeyframes(const plx::InMemoryDataset& data,
                                       const std::vector<int>& indices,
                                       const std::vector<plx::SE3>& poses,
                                       const std::vector<plx::SE3>& truth, bool loop_closure,
                                       bool refine_rebuild, bool keep_unmoved,
                                       bool in_place, const Flags& flags,
                                       const std::vector<int>& held_out) {
  plx::SlamOptions o = plx::DefaultSlamOptions();
  o.deterministic = true;
  o.mapping.iterations_per_keyframe = flags.iterations;
  o.refinement.window = 0;  // the graph corrects the poses handed in, nothing else moves them
  o.loop_closure.enabled = loop_closure;
  plx::SlamSplitOptions split = plx::SplitSlamOptions(o);
  split.mapper.rebuild_refines_all = refine_rebuild;
  split.mapper.rebuild_keeps_unmoved = keep_unmoved;
  if (!in_place) split.mapper.in_place_max_shift_m = 0.0;
  std::unique_ptr<plx::Backend> backend = plx::MakeCpuBackend(0);
  plx::SlamCoordinator coordinator(split.mapper, split.gate);
  if (absl::Status s = coordinator.StartMapper(backend.get()); !s.ok()) return s;
  const plx::PinholeIntrinsics& k = data.calibration().pinhole;
  const auto start = Clock::now();
  int segment = 0;
  // The camera's frame: the drifting odometry's, moved by every correction it has seen (as
  // SlamTracker::FollowCorrection moves a camera).
  plx::SE3 camera_change;
  int generation = 0;
  for (size_t i = 0; i < indices.size(); ++i) {
    absl::StatusOr<plx::RgbdFrame> frame = data.LoadFrame(indices[i]);
    if (!frame.ok()) return frame.status();
    frame->ground_truth.reset();
    absl::StatusOr<plx::FrameFeatures> features =
        plx::ExtractFrameFeatures(*frame, k, plx::FrameFeatureOptions{});
    if (!features.ok()) return features.status();
    plx::SlamFrameResult result;
    result.keyframe = true;
    result.pose = poses[i];
    result.features = std::make_shared<const plx::FrameFeatures>(*std::move(features));
    if (const auto seen = coordinator.correction();
        seen != nullptr && seen->generation > generation) {
      camera_change = seen->FrameChangeAt(camera_change * poses[i - 1]) * camera_change;
      generation = seen->generation;
    }
    result.pose = camera_change * poses[i];
    result.correction_generation = generation;
    if (absl::Status s = coordinator.Accept(*frame, k, &result, &segment).status(); !s.ok()) {
      return s;
    }
    for (;;) {
      absl::StatusOr<plx::SlamStepResult> r = coordinator.Step(plx::SlamStepMode::kMap);
      if (!r.ok()) return r.status();
      if (r->out_of_work) break;
    }
  }
  for (;;) {
    absl::StatusOr<plx::SlamStepResult> r = coordinator.Step(plx::SlamStepMode::kFinish);
    if (!r.ok()) return r.status();
    if (r->out_of_work) break;
  }
  RunResult out;
  out.seconds = Seconds(start);
  for (const plx::StampedPose& p : coordinator.keyframe_poses()) out.keyframes.push_back(p.pose);
  out.progress = coordinator.progress();
  for (const plx::LoopEdge& loop : coordinator.loops()) {
    const plx::SE3 real = truth[loop.from].Inverse() * truth[loop.to];
    const bool wrong = (real.translation() - loop.from_T_to.translation()).norm() > 0.05 ||
                       plx::RotationAngleBetween(real, loop.from_T_to) > 2.0 * kPi / 180.0;
    out.false_loops += wrong;
  }
  const plx::SlamMapVersion latest = coordinator.latest();
  if (latest.map == nullptr) return absl::InternalError("no map");
  absl::StatusOr<plx::MapEvalResult> eval =
      plx::EvaluateMap(*backend, *latest.map, data, held_out);
  if (!eval.ok()) return eval.status();
  out.eval = *eval;
  absl::StatusOr<plx::AteResult> ate =
      plx::ComputeAte(out.keyframes, truth, plx::TrajectoryAlignment::kSE3);
  if (!ate.ok()) return ate.status();
  const plx::SE3 truth_T_map(Eigen::Quaterniond(ate->alignment.rotation),
                             ate->alignment.translation);
  std::vector<plx::RgbdFrame> frames = data.frames();
  for (plx::RgbdFrame& f : frames) {
    if (f.ground_truth) f.ground_truth = truth_T_map.Inverse() * *f.ground_truth;
  }
  const plx::InMemoryDataset in_map_frame("aligned", data.calibration(), std::move(frames));
  absl::StatusOr<plx::MapEvalResult> aligned =
      plx::EvaluateMap(*backend, *latest.map, in_map_frame, held_out);
  if (!aligned.ok()) return aligned.status();
  out.aligned_eval = *aligned;
  return out;
}

int TwoLapLoop(const Flags& flags) {
  plx::SyntheticOptions s;
  s.width = flags.width;
  s.height = flags.height;
  s.fps = 5.0;  // keyframes are every other frame (0.4 s); held-out frames between them
  s.num_frames = static_cast<int>(12.0 * flags.laps * s.fps) + 1;
  absl::StatusOr<plx::InMemoryDataset> data = plx::GenerateSyntheticSequence(s);
  if (!data.ok()) {
    std::fprintf(stderr, "%s\n", data.status().ToString().c_str());
    return 1;
  }
  const std::vector<int> indices = plx::KeyframeIndices(s.num_frames, 2);
  const std::vector<int> held_out = plx::HeldOutFrames(s.num_frames, 2, 20);
  std::vector<plx::SE3> truth, drifted;
  for (int i : indices) truth.push_back(*data->ground_truth(i));
  drifted.push_back(truth[0]);
  const size_t drift_start = static_cast<size_t>(flags.drift_from * truth.size());
  for (size_t i = 1; i < truth.size(); ++i) {
    const plx::SE3 bias = i > drift_start ? Bias(flags) : plx::SE3();
    drifted.push_back(drifted.back() * truth[i - 1].Inverse() * truth[i] * bias);
  }
  std::printf("two-lap loop: %dx%d, %d laps, %zu keyframes, drift %.2f deg + %.1f cm per step "
              "from keyframe %zu, %d iterations per keyframe\n",
              flags.width, flags.height, flags.laps, indices.size(), flags.yaw_drift_deg,
              flags.creep_cm, drift_start, flags.iterations);
  std::printf("%-22s %9s %9s %9s %6s %6s %6s %9s %7s %9s %7s %7s\n", "run", "end_cm", "mean_cm",
              "ate_cm", "loops", "false", "corr", "depthL1", "psnr", "alignL1", "apsnr",
              "secs");
  struct Case {
    const char* key;
    const char* name;
    const std::vector<plx::SE3>* poses;
    bool loop_closure;
    bool refine_rebuild;
    bool keep_unmoved;
    bool in_place;
  };
  for (const Case& c :
       {Case{"true", "true poses", &truth, false, true, false, true},
        Case{"drift", "drift, no loop closure", &drifted, false, true, false, true},
        Case{"loop", "drift, loop closure", &drifted, true, true, false, true},
        Case{"loop-rebuild", "drift, LC, all rebuilt", &drifted, true, true, false, false},
        Case{"loop-seeded", "drift, LC, seeded", &drifted, true, true, true, false},
        Case{"loop-unrefined", "drift, LC, unrefined", &drifted, true, false, false, false}}) {
    if (!absl::StrContains(absl::StrCat(",", flags.cases, ","), absl::StrCat(",", c.key, ","))) {
      continue;
    }
    absl::StatusOr<RunResult> r =
        RunKeyframes(*data, indices, *c.poses, truth, c.loop_closure, c.refine_rebuild,
                     c.keep_unmoved, c.in_place, flags, held_out);
    if (!r.ok()) {
      std::fprintf(stderr, "%s: %s\n", c.name, r.status().ToString().c_str());
      return 1;
    }
    double sum = 0.0;
    for (size_t i = 0; i < truth.size(); ++i) {
      sum += (r->keyframes[i].translation() - truth[i].translation()).norm();
    }
    absl::StatusOr<plx::AteResult> ate =
        plx::ComputeAte(r->keyframes, truth, plx::TrajectoryAlignment::kSE3);
    const double end =
        (r->keyframes.back().translation() - truth.back().translation()).norm();
    std::printf("%-22s %9.2f %9.2f %9.2f %6d %6d %6d %8.2fcm %7.2f %8.2fcm %7.2f %7.1f\n",
                c.name, 100 * end, 100 * sum / truth.size(),
                ate.ok() ? 100 * ate->translation_m.rmse : -1.0, r->progress.loops.accepted,
                r->false_loops, r->progress.loops.corrections, 100 * r->eval.depth_l1_m,
                r->eval.psnr, 100 * r->aligned_eval.depth_l1_m, r->aligned_eval.psnr,
                r->seconds);
    std::fflush(stdout);
    if (c.loop_closure) {
      std::printf("  loop closure: %d keyframes checked, %d proposed, %d verified, %d rejected, "
                  "last solve %.1f ms moving keyframes up to %.1f cm; %d of the corrections "
                  "in place; last rebuild: %d keyframes moved, %lld bricks kept, %lld dropped\n",
                  r->progress.loops.checked, r->progress.loops.proposed,
                  r->progress.loops.verified, r->progress.loops.rejected,
                  r->progress.loops.last_solve_ms, 100 * r->progress.loops.last_shift_m,
                  r->progress.loops.in_place, r->progress.loops.last_moved_keyframes,
                  static_cast<long long>(r->progress.loops.last_kept_bricks),
                  static_cast<long long>(r->progress.loops.last_dropped_bricks));
    }
  }
  return 0;
}

// A drifting chain of `n` keyframes on a circle (two laps), loop edges from the second lap.
void GraphSolves() {
  std::printf("pose-graph solve (two laps, a loop edge every 10th keyframe of the second):\n");
  std::printf("%10s %6s %9s %10s %10s %12s %12s\n", "keyframes", "loops", "rejected",
              "median_ms", "max_ms", "end_before_cm", "end_err_cm");
  for (int n : {100, 500, 1000}) {
    const int lap = n / 2;
    std::vector<plx::SE3> truth;
    for (int i = 0; i < n; ++i) {
      const double a = 2.0 * kPi * i / lap;
      truth.emplace_back(
          Eigen::AngleAxisd(a + kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix(),
          Eigen::Vector3d(3.0 * std::cos(a), 0.0, 3.0 * std::sin(a)));
    }
    // Odometry that drifts 3 degrees of yaw per lap and creeps 1 % of each step forward,
    // whatever the keyframe spacing (a bias per step would make long laps absurd).
    const double step_m = 2.0 * kPi * 3.0 / lap;
    const plx::SE3 bias(
        Eigen::AngleAxisd(3.0 * kPi / 180.0 / lap, Eigen::Vector3d::UnitY()).toRotationMatrix(),
        Eigen::Vector3d(0.0, 0.0, 0.01 * step_m));
    std::vector<plx::SE3> drifted = {truth[0]};
    for (int i = 1; i < n; ++i) {
      drifted.push_back(drifted.back() * truth[i - 1].Inverse() * truth[i] * bias);
    }
    std::vector<plx::LoopEdge> loops;
    for (int i = lap; i < n; i += 10) {
      loops.push_back({i - lap, i, truth[i - lap].Inverse() * truth[i]});
    }
    plx::LoopClosureOptions options;
    options.graph.max_solve_seconds = 10.0;  // measure the solve, not the bound
    std::vector<double> ms;
    double end = 0.0;
    int rejected = 0;
    for (int run = 0; run < 5; ++run) {
      absl::StatusOr<plx::LoopCorrection> c = plx::CorrectKeyframes(drifted, loops, options);
      if (!c.ok()) {
        std::fprintf(stderr, "%s\n", c.status().ToString().c_str());
        return;
      }
      ms.push_back(1e3 * c->solve_seconds);
      end = (c->poses.back().translation() - truth.back().translation()).norm();
      rejected = static_cast<int>(c->rejected_loops.size());
    }
    const double before = (drifted.back().translation() - truth.back().translation()).norm();
    std::printf("%10d %6zu %9d %10.1f %10.1f %12.2f %12.2f\n", n, loops.size(), rejected,
                Median(ms), *std::max_element(ms.begin(), ms.end()), 100 * before, 100 * end);
  }
}

void RankingTimes() {
  plx::SyntheticOptions s;
  s.width = 320;
  s.height = 240;
  s.num_frames = 24;
  absl::StatusOr<plx::InMemoryDataset> data = plx::GenerateSyntheticSequence(s);
  if (!data.ok()) return;
  std::vector<plx::FrameFeatures> features;
  for (int i = 0; i < s.num_frames; ++i) {
    absl::StatusOr<plx::RgbdFrame> f = data->LoadFrame(i);
    if (!f.ok()) return;
    absl::StatusOr<plx::FrameFeatures> ff =
        plx::ExtractFrameFeatures(*f, data->calibration().pinhole, plx::FrameFeatureOptions{});
    if (!ff.ok()) return;
    features.push_back(*std::move(ff));
  }
  std::printf("place recognition (thumbnail ranking of one keyframe against N):\n");
  for (int n : {100, 1000, 5000}) {
    std::vector<plx::RelocalisationKeyframe> keyframes;
    for (int i = 0; i < n; ++i) keyframes.push_back({&features[i % features.size()], {}});
    std::vector<double> us;
    for (int run = 0; run < 20; ++run) {
      const auto start = Clock::now();
      const std::vector<int> ranked = plx::RankKeyframes(features[run % features.size()],
                                                         keyframes, 3, 0.3f);
      us.push_back(1e6 * Seconds(start));
      if (ranked.empty()) std::printf("  (nothing ranked)\n");
    }
    std::printf("  %5d keyframes: median %.0f us\n", n, Median(us));
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // rows as they come, also into a file
  Flags flags;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--graph-only") {
      flags.graph_only = true;
      continue;
    }
    if (flag == "--help" || flag == "-h") {
      std::printf("usage: %s [--width W --height H --laps N --iterations N --yaw-drift-deg D\n"
                  "        --creep-cm C --drift-from F --graph-only --cases LIST]\n"
                  "  LIST: any of true,drift,loop,loop-rebuild,loop-seeded,loop-unrefined\n"
                  "  (what each prints: the comment at the top of bench/loop_closure_bench.cc)\n",
                  argv[0]);
      return 0;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n", argv[i]);
      return 2;
    }
    const char* value = argv[++i];
    if (flag == "--width") flags.width = std::atoi(value);
    else if (flag == "--height") flags.height = std::atoi(value);
    else if (flag == "--laps") flags.laps = std::atoi(value);
    else if (flag == "--iterations") flags.iterations = std::atoi(value);
    else if (flag == "--yaw-drift-deg") flags.yaw_drift_deg = std::atof(value);
    else if (flag == "--creep-cm") flags.creep_cm = std::atof(value);
    else if (flag == "--drift-from") flags.drift_from = std::atof(value);
    else if (flag == "--cases") flags.cases = value;
    else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  GraphSolves();
  RankingTimes();
  if (flags.graph_only) return 0;
  return TwoLapLoop(flags);
}

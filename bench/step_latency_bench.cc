// How long one MappingSession::Step runs while keyframes stream in (issue 12, point 3): a
// tracking frame on the same device waits for the step in progress, so the longest step bounds
// its latency. Keyframes 0, EVERY, 2*EVERY, ... of a dataset (ground-truth poses) are added one
// at a time, each followed by steps until the session has no work (lock-step, as SLAM's
// deterministic mode runs it), with the session's default options.
// Prints one line per keyframe (the steps it took until it counted as integrated, their total
// and longest duration) and a JSON object over every step: max and median duration, of all
// steps and of those that integrated.
// Usage: plx_step_latency_bench DATASET_DIR [KEYFRAMES=12] [EVERY=10] [ITERATIONS_PER_KEYFRAME]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/datasets/dataset.h"
#include "core/mapping/mapping_session.h"

namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "step_latency_bench: %s\n", status.ToString().c_str());
  return 1;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

double Max(const std::vector<double>& values) {
  return values.empty() ? 0.0 : *std::max_element(values.begin(), values.end());
}

}  // namespace

int main(int argc, char** argv) {
  using namespace plx;
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DATASET_DIR [KEYFRAMES=12] [EVERY=10] [ITERATIONS]\n", argv[0]);
    return 2;
  }
  const int keyframes = argc > 2 ? std::stoi(argv[2]) : 12;
  const int every = argc > 3 ? std::stoi(argv[3]) : 10;
  absl::StatusOr<std::unique_ptr<RgbdDataset>> dataset = OpenDataset(argv[1]);
  if (!dataset.ok()) return Fail(dataset.status());
  std::unique_ptr<Backend> backend = MakeCpuBackend();

  MappingSessionOptions options;
  if (argc > 4) options.iterations_per_keyframe = std::stoi(argv[4]);
  absl::StatusOr<std::unique_ptr<MappingSession>> session =
      MappingSession::Create(options, backend.get(), nullptr);
  if (!session.ok()) return Fail(session.status());
  const PinholeIntrinsics& k = (*dataset)->calibration().pinhole;

  std::vector<double> all_steps, integration_steps;
  for (int i = 0, index = 0; i < keyframes && index < (*dataset)->size(); ++i, index += every) {
    absl::StatusOr<RgbdFrame> frame = (*dataset)->LoadFrame(index);
    if (!frame.ok()) return Fail(frame.status());
    const std::optional<SE3> pose = (*dataset)->ground_truth(index);
    if (!pose) return Fail(absl::FailedPreconditionError("frame without ground truth"));
    if (absl::Status s = (*session)->AddKeyframe(*std::move(frame), *pose, k); !s.ok()) {
      return Fail(s);
    }
    // The steps up to and including the one after which the keyframe counts as integrated.
    int steps_to_integrate = 0;
    double integrate_total_s = 0.0, integrate_max_s = 0.0;
    while ((*session)->has_work()) {
      const bool integrating = (*session)->progress().keyframes_integrated <= i;
      const auto start = std::chrono::steady_clock::now();
      absl::StatusOr<MappingStepResult> step = (*session)->Step();
      const double seconds = Seconds(start);
      if (!step.ok()) return Fail(step.status());
      all_steps.push_back(seconds);
      if (integrating) {
        ++steps_to_integrate;
        integrate_total_s += seconds;
        integrate_max_s = std::max(integrate_max_s, seconds);
        integration_steps.push_back(seconds);
      }
    }
    std::fprintf(stderr,
                 "keyframe %d (frame %d): %d steps to integrate, %.3f s in all, longest %.3f s; "
                 "map %.1f MB\n",
                 i, index, steps_to_integrate, integrate_total_s, integrate_max_s,
                 (*session)->progress().map_bytes / 1e6);
  }
  const MappingSessionProgress p = (*session)->progress();
  std::printf(
      "{\"dataset\": \"%s\", \"keyframes\": %d, \"iterations\": %d, \"steps\": %zu, "
      "\"step_max_s\": %.4f, \"step_median_s\": %.4f, \"integration_steps\": %zu, "
      "\"integration_step_max_s\": %.4f, \"integration_step_median_s\": %.4f, \"map_mb\": %.1f}\n",
      (*dataset)->name().c_str(), p.keyframes_integrated, p.iterations, all_steps.size(),
      Max(all_steps), Median(all_steps), integration_steps.size(), Max(integration_steps),
      Median(integration_steps), p.map_bytes / 1e6);
  return 0;
}

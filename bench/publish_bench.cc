// Publish cost of a map version (issue "engine seams", point 3): a mapping session integrates
// keyframes of a dataset, then, after one more keyframe and one optimisation chunk, measures
//   full_copy_s: copying every brick (what publishing cost before copy-on-write versions),
//   publish_s:   a copy-on-write publish (the index and brick tables only),
//   next_chunk_s: the next optimisation chunk, which clones the bricks it changes (how many:
//                 next_chunk_cloned_bricks, at most the session's per-iteration cap), against
//                 plain_chunk_s, a chunk before the publish with nothing to clone.
// Prints one JSON object. Usage: plx_publish_bench DATASET_DIR [KEYFRAMES] [EVERY]
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
  std::fprintf(stderr, "publish_bench: %s\n", status.ToString().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace plx;
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DATASET_DIR [KEYFRAMES=8] [EVERY=20]\n", argv[0]);
    return 2;
  }
  const int keyframes = argc > 2 ? std::stoi(argv[2]) : 8;
  const int every = argc > 3 ? std::stoi(argv[3]) : 20;
  absl::StatusOr<std::unique_ptr<RgbdDataset>> dataset = OpenDataset(argv[1]);
  if (!dataset.ok()) return Fail(dataset.status());
  std::unique_ptr<Backend> backend = MakeCpuBackend();

  MappingSessionOptions options;
  options.mapper = MapperOptionsForVoxelSize(0.02f);
  options.iterations_per_keyframe = 10;
  options.min_publish_interval_s = 1e9;  // this program publishes by hand
  absl::StatusOr<std::unique_ptr<MappingSession>> session =
      MappingSession::Create(options, backend.get(), nullptr);
  if (!session.ok()) return Fail(session.status());
  const PinholeIntrinsics& k = (*dataset)->calibration().pinhole;
  auto add = [&](int index) -> absl::Status {
    absl::StatusOr<RgbdFrame> frame = (*dataset)->LoadFrame(index);
    if (!frame.ok()) return frame.status();
    const std::optional<SE3> pose = (*dataset)->ground_truth(index);
    if (!pose) return absl::FailedPreconditionError("frame without ground truth");
    return (*session)->AddKeyframe(*std::move(frame), *pose, k);
  };
  int index = 0;
  for (int i = 0; i < keyframes && index < (*dataset)->size(); ++i, index += every) {
    if (absl::Status s = add(index); !s.ok()) return Fail(s);
  }
  std::fprintf(stderr, "publish_bench: integrating %d keyframes\n", keyframes);
  while ((*session)->has_work()) {
    absl::StatusOr<MappingStepResult> step = (*session)->Step();
    if (!step.ok()) return Fail(step.status());
  }
  absl::StatusOr<std::shared_ptr<const PlenoxelMap>> before = (*session)->Publish();
  if (!before.ok()) return Fail(before.status());

  // One more keyframe and one chunk, then the publish under test.
  if (absl::Status s = add(index); !s.ok()) return Fail(s);
  absl::StatusOr<MappingStepResult> step = (*session)->Step();
  if (!step.ok()) return Fail(step.status());
  // A chunk with nothing to clone, for comparison with the one after the publish.
  absl::StatusOr<MappingStepResult> plain = (*session)->Step();
  if (!plain.ok()) return Fail(plain.status());
  const auto publish_start = std::chrono::steady_clock::now();
  absl::StatusOr<std::shared_ptr<const PlenoxelMap>> version = (*session)->Publish();
  const double publish_s = Seconds(publish_start);
  if (!version.ok()) return Fail(version.status());

  // The old publish: a deep copy of every brick (a shared copy made private throughout).
  const auto copy_start = std::chrono::steady_clock::now();
  PlenoxelMap deep = (*version)->ShareCopy();
  const std::vector<uint8_t> all(static_cast<size_t>(deep.grid.num_bricks()), 1);
  deep.grid.MakePrivate(all.data());
  const double full_copy_s = Seconds(copy_start);

  const int64_t cloned_before = (*session)->progress().cloned_bricks;
  absl::StatusOr<MappingStepResult> next = (*session)->Step();
  if (!next.ok()) return Fail(next.status());
  const MappingSessionProgress p = (*session)->progress();
  std::printf(
      "{\"dataset\": \"%s\", \"keyframes\": %d, \"bricks\": %lld, \"map_mb\": %.1f, "
      "\"full_copy_s\": %.4f, \"publish_s\": %.5f, \"next_chunk_iterations\": %d, "
      "\"next_chunk_cloned_bricks\": %lld, \"next_chunk_s\": %.4f, \"plain_chunk_iterations\": %d, "
      "\"plain_chunk_s\": %.4f}\n",
      (*dataset)->name().c_str(), p.keyframes_integrated,
      static_cast<long long>((*version)->grid.num_bricks()), p.map_bytes / 1e6, full_copy_s,
      publish_s, next->iterations, static_cast<long long>(p.cloned_bricks - cloned_before),
      next->optimize_s, plain->iterations, plain->optimize_s);
  return 0;
}

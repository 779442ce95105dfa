// Readers and a writer on one map at once, the daemon's situation without gRPC: a mapping
// session publishes copy-on-write versions while other threads track and render whichever
// version is the latest. Meant to run under ThreadSanitizer too (scripts/test.sh --tsan): a
// reader that saw a version change under it, or a write into a shared brick, is a data race.
#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/mapping/mapping_session.h"
#include "core/render/render_view.h"
#include "core/tracking/tracker.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

TEST(ConcurrentReadersTest, TrackAndRenderPublishedVersionsWhileMappingPublishes) {
  std::unique_ptr<InMemoryDataset> dataset = testing::MakeSyntheticRoom(64, 48, 30);
  ASSERT_NE(dataset, nullptr);
  const PinholeIntrinsics& k = dataset->calibration().pinhole;

  MappingSessionOptions options;
  options.mapper = MapperOptionsForVoxelSize(0.04f);
  options.mapper.batch_size = 1024;
  options.iterations_per_keyframe = 20;
  options.chunk_iterations = 2;
  options.min_publish_interval_s = 0.0;
  options.publish_every_iterations = 2;
  std::unique_ptr<Backend> mapping_backend = MakeCpuBackend(1);
  auto session = MappingSession::Create(options, mapping_backend.get(), nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  const RgbdFrame& first = dataset->frames()[0];
  ASSERT_TRUE((*session)->AddKeyframe(first, *first.ground_truth, k).ok());
  // Integration runs in bounded slices (MappingSession::Step): step until the first version.
  absl::StatusOr<MappingStepResult> step = (*session)->Step();
  for (int i = 0; i < 1000 && step.ok() && step->published == nullptr; ++i) {
    step = (*session)->Step();
  }
  ASSERT_TRUE(step.ok() && step->published != nullptr);

  // The store: readers take the latest version under the lock and keep their shared_ptr.
  std::mutex mutex;
  std::shared_ptr<const PlenoxelMap> latest = step->published;
  auto take = [&] {
    std::lock_guard<std::mutex> lock(mutex);
    return latest;
  };
  std::atomic<bool> done{false};
  std::atomic<int> tracked{0}, rendered{0}, failures{0};

  std::vector<std::thread> readers;
  for (int r = 0; r < 2; ++r) {
    readers.emplace_back([&, r] {
      std::unique_ptr<Backend> backend = MakeCpuBackend(1);
      std::shared_ptr<const PlenoxelMap> map = take();
      TrackerOptions to;
      to.rays = 256;
      to.iterations = 3;
      Tracker tracker(map.get(), backend.get(), to);
      const RgbdFrame& f = dataset->frames()[1 + r];
      while (!done.load()) {
        map = take();  // keeps the version alive while this thread reads it
        tracker.set_map(map.get());
        tracker.Reset(*f.ground_truth, f.timestamp - 1.0 / 30);
        absl::StatusOr<TrackingResult> t = tracker.Track(f, k);
        absl::StatusOr<RenderedView> v = RenderView(*backend, *map, *f.ground_truth, k);
        if (!t.ok() || !v.ok()) failures++;
        tracked++;
        rendered++;
      }
    });
  }
  for (int f : {10, 20}) {
    const RgbdFrame& frame = dataset->frames()[f];
    ASSERT_TRUE((*session)->AddKeyframe(frame, *frame.ground_truth, k).ok());
  }
  int published = 1;
  while ((*session)->has_work()) {
    absl::StatusOr<MappingStepResult> s = (*session)->Step(/*finish=*/true);
    ASSERT_TRUE(s.ok()) << s.status();
    if (s->published) {
      std::lock_guard<std::mutex> lock(mutex);
      latest = s->published;
      ++published;
    }
  }
  // Let the readers see the last version too.
  const int seen = tracked.load();
  while (tracked.load() < seen + 2) std::this_thread::yield();
  done = true;
  for (std::thread& t : readers) t.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_GT(published, 5);
  EXPECT_GT(tracked.load(), 2);
}

}  // namespace
}  // namespace plx

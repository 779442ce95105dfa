// A map's SLAM job without gRPC: the daemon's state built from its real parts (the map store,
// one CPU device worker, the job registry, the SLAM job registry), keyframes handed in as the
// Slam streams would. Joining and leaving, keyframes before the mapper exists, the versions a
// tracker sees (the store's numbers), draining, errors, and the registry/job lock order.
#include "server/slam_job.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "core/cpu/cpu_backend.h"
#include "core/slam/slam_session.h"
#include "tests/synthetic_room.h"

namespace plx::server {
namespace slam_job_test {

using ::testing::HasSubstr;

constexpr char kMap[] = "room";
constexpr float kVoxel = 0.02f;
// Long enough for a loaded CI machine; a healthy run takes well under a second per wait.
constexpr auto kWait = std::chrono::seconds(120);

SlamSplitOptions SmallSplit(int iterations_per_keyframe, bool deterministic = false) {
  SlamOptions o = DefaultSlamOptions();
  o.deterministic = deterministic;
  o.tracker.rays = 512;
  o.mapping.mapper = MapperOptionsForVoxelSize(kVoxel);
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.batch_size = 1024;
  o.mapping.iterations_per_keyframe = iterations_per_keyframe;
  o.refinement.window = 0;
  return SplitSlamOptions(o);
}

// Polls `done` until it holds; false after kWait.
bool Eventually(const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + kWait;
  while (!done()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

// One Slam stream's side of the job: its listener and what the job told it. Like the stream
// (SlamReactor::OnJobChanged), the notification reads the job's status, so the listener's lock,
// then the job's, are taken from the job's notifying thread.
class Stream {
 public:
  Stream() : listener_(std::make_shared<SlamJobListener>([this] { Changed(); })) {}
  ~Stream() { listener_->Reset(); }

  const std::shared_ptr<SlamJobListener>& listener() const { return listener_; }
  void Bind(std::shared_ptr<SlamJob> job) {
    std::lock_guard<std::mutex> lock(mutex_);
    job_ = std::move(job);
  }
  bool saw_finished() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return saw_finished_;
  }
  // Waits until `done` holds, re-checking whenever the job notifies (and every 20 ms).
  bool WaitUntil(const std::function<bool()>& done) {
    const auto deadline = std::chrono::steady_clock::now() + kWait;
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      const uint64_t seen = notifications_;
      lock.unlock();
      if (done()) return true;
      lock.lock();
      if (std::chrono::steady_clock::now() >= deadline) return false;
      changed_.wait_for(lock, std::chrono::milliseconds(20),
                        [&] { return notifications_ != seen; });
    }
  }

 private:
  void Changed() {
    std::shared_ptr<SlamJob> job;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      job = job_;
    }
    const bool finished = job != nullptr && job->Status().finished;
    std::lock_guard<std::mutex> lock(mutex_);
    saw_finished_ = saw_finished_ || finished;
    ++notifications_;
    changed_.notify_all();
  }

  const std::shared_ptr<SlamJobListener> listener_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::shared_ptr<SlamJob> job_;
  uint64_t notifications_ = 0;
  bool saw_finished_ = false;
};

// Holds the worker with a task of its own until Open, so the job's tasks wait in its queue: the
// test then sees the job between steps (no step in progress).
class WorkerGate {
 public:
  explicit WorkerGate(DeviceWorker& worker) {
    auto running = std::make_shared<std::promise<void>>();
    std::future<void> started = running->get_future();
    worker.Post(Priority::kInteractive,
                [running, open = open_.get_future().share()](Backend*, bool cancelled) {
                  running->set_value();
                  if (!cancelled) open.wait();
                });
    started.wait();
  }
  ~WorkerGate() { Open(); }
  void Open() {
    if (opened_) return;
    opened_ = true;
    open_.set_value();
  }

 private:
  std::promise<void> open_;
  bool opened_ = false;
};

class SlamJobTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { room_ = plx::testing::MakeSyntheticRoom(80, 60, 12).release(); }
  static void TearDownTestSuite() {
    delete room_;
    room_ = nullptr;
  }

  SlamJobTest() : maps_(MapStoreOptions{}) {
    std::vector<std::unique_ptr<DeviceWorker>> workers;
    workers.push_back(std::make_unique<DeviceWorker>(
        MakeCpuBackend(1), DeviceDescription{"cpu", "cpu", "cpu (1 thread)"}));
    workers_ = std::make_unique<WorkerPool>(std::move(workers));
    slam_jobs_ = std::make_unique<SlamJobs>(&state_);
    state_.maps = &maps_;
    state_.workers = workers_.get();
    state_.jobs = &jobs_;
    state_.slam_jobs = slam_jobs_.get();
  }
  // The daemon's order: the workers stop first (a queued task then ends its job, which leaves
  // the registry), then the jobs go (each unbinds from its worker).
  ~SlamJobTest() override {
    workers_->StopAll();
    slam_jobs_.reset();
  }

  void SetUp() override {
    ASSERT_NE(room_, nullptr);
    ASSERT_TRUE(maps_.Create(kMap, kVoxel).ok());
  }

  DeviceWorker& worker() { return workers_->worker(0); }

  std::shared_ptr<SlamJob> Join(Stream& stream, const SlamSplitOptions& split,
                                bool mapping_set = false) {
    absl::StatusOr<std::shared_ptr<SlamJob>> job =
        slam_jobs_->Join(kMap, split, mapping_set, stream.listener());
    EXPECT_TRUE(job.ok()) << job.status();
    if (!job.ok()) return nullptr;
    stream.Bind(*job);
    return *job;
  }
  absl::Status AddKeyframe(SlamJob& job, int i) {
    SlamFrameResult keyframe;
    keyframe.keyframe = true;
    keyframe.pose = *room_->ground_truth(i);
    int segment = 0;
    return job.Accept(room_->frames()[i], room_->calibration().pinhole, &keyframe, &segment,
                      /*camera=*/0);
  }
  uint64_t StoreVersion() {
    absl::StatusOr<MapVersion> latest = maps_.Latest(kMap);
    EXPECT_TRUE(latest.ok()) << latest.status();
    return latest.ok() ? latest->version : 0;
  }
  bool LeaseHeld() {
    absl::StatusOr<MapStatus> info = maps_.Info(kMap);
    EXPECT_TRUE(info.ok()) << info.status();
    return info.ok() && info->mapping;
  }
  JobState RegistryState(const std::string& id) {
    absl::StatusOr<JobInfo> info = jobs_.Get(id);
    EXPECT_TRUE(info.ok()) << info.status();
    return info.ok() ? info->state : JobState::kQueued;
  }

  static InMemoryDataset* room_;
  MapStore maps_;
  JobRegistry jobs_;
  DaemonState state_;
  std::unique_ptr<WorkerPool> workers_;
  std::unique_ptr<SlamJobs> slam_jobs_;
};

InMemoryDataset* SlamJobTest::room_ = nullptr;

TEST_F(SlamJobTest, StreamsOnOneMapShareOneJob) {
  Stream a, b, c, d;
  std::shared_ptr<SlamJob> job = Join(a, SmallSplit(10));
  ASSERT_NE(job, nullptr);
  EXPECT_TRUE(LeaseHeld());
  // The same options given explicitly are the job's: joined.
  EXPECT_EQ(Join(b, SmallSplit(10), /*mapping_set=*/true), job);
  EXPECT_EQ(slam_jobs_->RunningOn(kMap), job);
  EXPECT_EQ(job->Status().streams, 2);
  EXPECT_EQ(job->Status().job_id, "slam-1");

  // Other mapping options, or the other mode, cannot join the running job.
  absl::StatusOr<std::shared_ptr<SlamJob>> other =
      slam_jobs_->Join(kMap, SmallSplit(20), /*mapping_set=*/true, c.listener());
  EXPECT_EQ(other.status().code(), absl::StatusCode::kFailedPrecondition) << other.status();
  EXPECT_THAT(other.status().message(), HasSubstr("iterations_per_keyframe 10"));
  absl::StatusOr<std::shared_ptr<SlamJob>> locked =
      slam_jobs_->Join(kMap, SmallSplit(10, /*deterministic=*/true), false, d.listener());
  EXPECT_EQ(locked.status().code(), absl::StatusCode::kFailedPrecondition) << locked.status();
  EXPECT_THAT(locked.status().message(), HasSubstr("is not deterministic"));
  EXPECT_EQ(job->Status().streams, 2);
  EXPECT_EQ(jobs_.Get("slam-2").status().code(), absl::StatusCode::kNotFound)
      << "a refused stream started a job";
  // While the job holds the map, Integrate is refused.
  EXPECT_EQ(maps_.BeginMapping(kMap, MappingJobKind::kIntegrate).code(),
            absl::StatusCode::kFailedPrecondition);

  job->Leave(a.listener());
  job->Leave(a.listener());  // idempotent: b is still on the job
  EXPECT_EQ(job->Status().streams, 1);
  EXPECT_FALSE(job->Status().finished);
  job->Leave(b.listener());
  // No keyframe came, so no task: the job ends at once and gives the map back.
  EXPECT_TRUE(job->Status().finished);
  EXPECT_TRUE(job->Status().error.ok());
  EXPECT_FALSE(LeaseHeld());
  EXPECT_EQ(slam_jobs_->RunningOn(kMap), nullptr);
  EXPECT_EQ(RegistryState("slam-1"), JobState::kDone);

  // The next stream starts a new job, with a new record for the viewer.
  std::shared_ptr<const TrajectoryRecord> old_record = slam_jobs_->Trajectory(kMap);
  Stream e;
  std::shared_ptr<SlamJob> next = Join(e, SmallSplit(20));
  ASSERT_NE(next, nullptr);
  EXPECT_NE(next, job);
  EXPECT_EQ(next->Status().job_id, "slam-2");
  EXPECT_NE(slam_jobs_->Trajectory(kMap), old_record);
  next->Leave(e.listener());
}

TEST_F(SlamJobTest, AKeyframeHandedBeforeTheMapperStartsIsIntegrated) {
  Stream stream;
  std::shared_ptr<SlamJob> job;
  {
    // The mapper is made by the job's first task: held back here, so the keyframe waits in
    // the coordinator.
    WorkerGate gate(worker());
    job = Join(stream, SmallSplit(10));
    ASSERT_NE(job, nullptr);
    ASSERT_TRUE(AddKeyframe(*job, 0).ok());
    const SlamMapView view = job->View();
    EXPECT_EQ(view.map, nullptr);
    EXPECT_EQ(view.version, 0);
    ASSERT_EQ(view.accepted_keyframes.size(), 1u);
    EXPECT_EQ(view.accepted_keyframes[0].timestamp, room_->frames()[0].timestamp);
    EXPECT_TRUE(view.mapping_behind());
    const SlamMapperProgress p = job->Status().mapping;
    EXPECT_EQ(p.keyframes, 1);
    EXPECT_EQ(p.keyframes_integrated, 0);
    EXPECT_EQ(p.pending_keyframes, 1);
    // A camera needs a first version, whatever its bound.
    EXPECT_FALSE(job->MayCameraProceed(4));
    EXPECT_EQ(StoreVersion(), 1u) << "published before the mapper ran";
  }
  ASSERT_TRUE(stream.WaitUntil([&] { return job->MayCameraProceed(0); }));
  const SlamMapperProgress p = job->Status().mapping;
  EXPECT_EQ(p.keyframes_integrated, 1);
  EXPECT_EQ(p.pending_keyframes, 0);
  const SlamMapView view = job->View();
  ASSERT_NE(view.map, nullptr);
  EXPECT_GT(view.map->grid.num_bricks(), 0);
  EXPECT_EQ(view.keyframe_poses.size(), 1u);
  ASSERT_TRUE(stream.WaitUntil([&] { return job->trajectory().Keyframes().size() == 1; }));
  job->Leave(stream.listener());
  ASSERT_TRUE(stream.WaitUntil([&] { return job->Status().finished; }));
}

TEST_F(SlamJobTest, TheViewCarriesTheStoresVersionOfTheMap) {
  // A first job maps keyframe 0; then another writer publishes twice (as an Integrate stream
  // would), so the store's numbers run ahead of any count a mapper could keep itself.
  {
    Stream first;
    std::shared_ptr<SlamJob> job = Join(first, SmallSplit(10));
    ASSERT_NE(job, nullptr);
    ASSERT_TRUE(AddKeyframe(*job, 0).ok());
    job->Leave(first.listener());
    ASSERT_TRUE(first.WaitUntil([&] { return job->Status().finished; }));
    EXPECT_EQ(job->Status().mapping.map_version, static_cast<int64_t>(StoreVersion()));
  }
  absl::StatusOr<MapVersion> base = maps_.Latest(kMap);
  ASSERT_TRUE(base.ok()) << base.status();
  ASSERT_GT(base->map->grid.num_bricks(), 0);
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(maps_.Publish(kMap, base->map, 0).ok());
  const uint64_t before = StoreVersion();
  ASSERT_EQ(before, base->version + 2);

  Stream stream;
  std::shared_ptr<SlamJob> job = Join(stream, SmallSplit(10));
  ASSERT_NE(job, nullptr);
  // Before any keyframe: the map the job extends, with the store's number for it.
  SlamMapView view = job->View();
  EXPECT_EQ(view.map.get(), base->map.get());
  EXPECT_EQ(view.version, static_cast<int64_t>(before));
  EXPECT_EQ(job->Status().mapping.map_version, static_cast<int64_t>(before));

  ASSERT_TRUE(AddKeyframe(*job, 6).ok());
  ASSERT_TRUE(stream.WaitUntil([&] { return job->Status().mapping.idle; }));
  {
    WorkerGate gate(worker());  // no step in progress while the two are compared
    absl::StatusOr<MapVersion> latest = maps_.Latest(kMap);
    ASSERT_TRUE(latest.ok()) << latest.status();
    view = job->View();
    EXPECT_GT(latest->version, before);
    EXPECT_EQ(view.version, static_cast<int64_t>(latest->version));
    EXPECT_EQ(view.map.get(), latest->map.get());
    EXPECT_EQ(job->Status().mapping.map_version, static_cast<int64_t>(latest->version));
    absl::StatusOr<MapStatus> info = maps_.Info(kMap);
    ASSERT_TRUE(info.ok()) << info.status();
    EXPECT_EQ(info->keyframes, 2) << "the store counts the keyframes each version brought";
  }
  job->Leave(stream.listener());
  ASSERT_TRUE(stream.WaitUntil([&] { return job->Status().finished; }));
  EXPECT_EQ(job->View().version, static_cast<int64_t>(StoreVersion()));
}

TEST_F(SlamJobTest, TheLastStreamLeavingSpendsTheBudgetThenReleasesTheMap) {
  constexpr int kIterations = 40;
  Stream stream;
  std::shared_ptr<SlamJob> job;
  {
    WorkerGate gate(worker());
    job = Join(stream, SmallSplit(kIterations));
    ASSERT_NE(job, nullptr);
    ASSERT_TRUE(AddKeyframe(*job, 0).ok());
    job->Leave(stream.listener());
    EXPECT_EQ(job->Status().streams, 0);
    EXPECT_FALSE(job->Status().finished) << "ended before the keyframe was mapped";
    EXPECT_TRUE(LeaseHeld());
  }
  const std::string id = job->Status().job_id;
  // The stream has left but is still told of the end (it waits for the final version).
  ASSERT_TRUE(stream.WaitUntil([&] { return stream.saw_finished(); }));
  ASSERT_TRUE(slam_jobs_->WaitForAll(absl::Seconds(60)));

  const SlamJobStatus s = job->Status();
  EXPECT_TRUE(s.error.ok()) << s.error;
  EXPECT_EQ(s.mapping.keyframes_integrated, 1);
  EXPECT_EQ(s.mapping.mapping_iterations, kIterations) << "the rest of the budget was not spent";
  EXPECT_EQ(s.mapping.map_version, static_cast<int64_t>(StoreVersion()));
  EXPECT_FALSE(LeaseHeld());
  EXPECT_EQ(slam_jobs_->RunningOn(kMap), nullptr);
  absl::StatusOr<JobInfo> info = jobs_.Get(id);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->state, JobState::kDone);
  EXPECT_EQ(info->message, absl::StrCat("1 keyframes, map version ", StoreVersion()));
  // An ended job takes no keyframe.
  const absl::Status late = AddKeyframe(*job, 1);
  EXPECT_EQ(late.code(), absl::StatusCode::kFailedPrecondition) << late;
  EXPECT_TRUE(maps_.BeginMapping(kMap, MappingJobKind::kIntegrate).ok());
  maps_.EndMapping(kMap);
}

TEST_F(SlamJobTest, DrainingIntegratesTheAcceptedKeyframesOnlyAndEnds) {
  constexpr int kIterations = 40;
  Stream stream;
  std::shared_ptr<SlamJob> job;
  {
    WorkerGate gate(worker());
    job = Join(stream, SmallSplit(kIterations));
    ASSERT_NE(job, nullptr);
    ASSERT_TRUE(AddKeyframe(*job, 0).ok());
    ASSERT_TRUE(AddKeyframe(*job, 4).ok());
    // The daemon drains: its streams are cancelled and leave.
    state_.draining = true;
    job->Leave(stream.listener());
    EXPECT_FALSE(job->Status().finished) << "ended with accepted keyframes unmapped";
  }
  ASSERT_TRUE(slam_jobs_->WaitForAll(absl::Seconds(60)));
  const SlamJobStatus s = job->Status();
  EXPECT_TRUE(s.finished);
  EXPECT_TRUE(s.error.ok()) << s.error;
  EXPECT_EQ(s.mapping.keyframes_integrated, 2);
  EXPECT_EQ(s.mapping.pending_keyframes, 0);
  // Only what integration needs: at most the chunk run between the two keyframes, far from
  // the 80 iterations the two keyframes earned.
  EXPECT_LE(s.mapping.mapping_iterations, job->options().mapping.chunk_iterations);
  // The save finds both keyframes in the store's latest version, the job's last.
  absl::StatusOr<MapStatus> info = maps_.Info(kMap);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->keyframes, 2);
  EXPECT_TRUE(info->dirty);
  EXPECT_FALSE(info->mapping);
  EXPECT_EQ(s.mapping.map_version, static_cast<int64_t>(info->version));
  absl::StatusOr<MapVersion> latest = maps_.Latest(kMap);
  ASSERT_TRUE(latest.ok());
  EXPECT_EQ(latest->map.get(), job->View().map.get());
  EXPECT_EQ(RegistryState(s.job_id), JobState::kDone);
  EXPECT_TRUE(stream.saw_finished());
}

TEST_F(SlamJobTest, ALockStepCameraWaitsUntilMappingIsIdle) {
  constexpr int kIterations = 30;
  Stream stream;
  std::shared_ptr<SlamJob> job = Join(stream, SmallSplit(kIterations, /*deterministic=*/true));
  ASSERT_NE(job, nullptr);
  ASSERT_TRUE(job->deterministic());
  ASSERT_TRUE(AddKeyframe(*job, 0).ok());
  ASSERT_TRUE(stream.WaitUntil([&] { return job->MayCameraProceed(0); }));
  // When the camera may go on, the keyframe has had every iteration it earned and the map that
  // has them is published: the next frame's view does not depend on timing.
  const SlamMapperProgress p = job->Status().mapping;
  EXPECT_EQ(p.mapping_iterations, kIterations);
  EXPECT_TRUE(p.idle);
  EXPECT_EQ(p.map_version, static_cast<int64_t>(StoreVersion()));
  ASSERT_TRUE(AddKeyframe(*job, 3).ok());
  EXPECT_FALSE(job->MayCameraProceed(0)) << "went on before the second keyframe was mapped";
  ASSERT_TRUE(stream.WaitUntil([&] { return job->MayCameraProceed(0); }));
  EXPECT_EQ(job->Status().mapping.mapping_iterations, 2 * kIterations);
  job->Leave(stream.listener());
  ASSERT_TRUE(stream.WaitUntil([&] { return job->Status().finished; }));
}

TEST_F(SlamJobTest, AMappingErrorEndsTheJobForEveryStream) {
  SlamSplitOptions split = SmallSplit(10);
  split.mapper.mapping.mapper.max_map_bytes = 1;  // no keyframe fits
  Stream a, b;
  std::shared_ptr<SlamJob> job = Join(a, split);
  ASSERT_NE(job, nullptr);
  ASSERT_EQ(Join(b, split), job);
  ASSERT_TRUE(AddKeyframe(*job, 0).ok());  // checked by the mapping task
  ASSERT_TRUE(a.WaitUntil([&] { return a.saw_finished() && b.saw_finished(); }));
  const SlamJobStatus s = job->Status();
  EXPECT_EQ(s.error.code(), absl::StatusCode::kResourceExhausted) << s.error;
  EXPECT_EQ(RegistryState(s.job_id), JobState::kFailed);
  EXPECT_FALSE(LeaseHeld());
  EXPECT_EQ(StoreVersion(), 1u);
  EXPECT_EQ(AddKeyframe(*job, 1).code(), absl::StatusCode::kFailedPrecondition);
  job->Leave(a.listener());
  job->Leave(b.listener());
  // The failed job is gone: the next stream starts over.
  Stream c;
  std::shared_ptr<SlamJob> next = Join(c, SmallSplit(10));
  ASSERT_NE(next, nullptr);
  EXPECT_NE(next, job);
  next->Leave(c.listener());
}

// Streams joining and leaving from several threads while the jobs they feed end and leave the
// registry, each stream's notification reading its job's status: the registry's lock is taken
// before a job's and a listener's before a job's, never the other way round (an inversion hangs
// here, and the watchdog aborts), and every job ends, gives the map back and unbinds from its
// worker. A stream's keyframe is refused only if it joined a job that had ended: a narrow
// window (SlamJobs::Join), which this only probes.
TEST_F(SlamJobTest, JoinsAndLeavesRacingTheJobsEnd) {
  constexpr int kThreads = 4;
  constexpr int kRounds = 12;
  const SlamSplitOptions split = SmallSplit(5);
  std::atomic<int> refused{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int r = 0; r < kRounds; ++r) {
        Stream stream;
        absl::StatusOr<std::shared_ptr<SlamJob>> job =
            slam_jobs_->Join(kMap, split, false, stream.listener());
        if (!job.ok()) {
          ADD_FAILURE() << job.status();
          continue;
        }
        stream.Bind(*job);
        if ((r + t) % 2 == 0 && !AddKeyframe(**job, (r + t) % 12).ok()) ++refused;
        (*job)->Leave(stream.listener());
      }
    });
  }
  std::promise<void> joined;
  std::thread watchdog([done = joined.get_future()]() mutable {
    if (done.wait_for(kWait) == std::future_status::timeout) {
      std::fprintf(stderr, "SlamJobTest: streams still running after %lld s: a deadlock\n",
                   static_cast<long long>(kWait.count()));
      std::abort();
    }
  });
  for (std::thread& t : threads) t.join();
  joined.set_value();
  watchdog.join();
  EXPECT_EQ(refused.load(), 0) << "a stream joined a job that had ended";
  ASSERT_TRUE(slam_jobs_->WaitForAll(absl::Seconds(60)));
  EXPECT_EQ(jobs_.running(), 0);
  EXPECT_FALSE(LeaseHeld());
  // The last tasks let go of their jobs, which unbind from the worker.
  EXPECT_TRUE(Eventually([&] { return worker().streams() == 0; }));
}

}  // namespace slam_job_test
}  // namespace plx::server

// Streams under load and interruption: concurrent trackers while a mapping job publishes new
// versions, latest-wins dropping, and clients that cancel mid-stream.
#include <atomic>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

// 0, 1, ..., kFrames - 1, kFrames - 2, ..., 0, 1, ...: an endless path that stays in the map.
int PingPong(int i) {
  const int period = 2 * (kFrames - 1);
  const int j = i % period;
  return j < kFrames ? j : period - j;
}

struct TrackerLog {
  std::string map;
  grpc::Status status;
  int sent = 0;
  std::vector<pb::PoseEstimate> estimates;
};

// 8 lock-step trackers (4 per map, each from its own thread and starting frame) run while an
// Integrate stream adds keyframes to map "a": every stream ends OK, every frame gets its
// estimate, trackers of "a" follow the versions the job publishes, and WatchJob reports the job
// RUNNING, then DONE.
TEST(StreamsTest, EightTrackersWhileMappingOneOfTheirMaps) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"a", "b"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::MapInfo a_before, b_before;
  ASSERT_TRUE(GetMap(*d.stub, "a", &a_before).ok());
  ASSERT_TRUE(GetMap(*d.stub, "b", &b_before).ok());

  constexpr int kTrackers = 8;
  std::vector<TrackerLog> logs(kTrackers);
  std::atomic<int> first_estimates{0};
  std::atomic<bool> mapping_done{false};
  // The trackers' clock: MappingProgress messages received. Each tracker sends one frame per
  // message (and freely once the job is done), so the interactive tracking work between two
  // mapping chunks is bounded and the background job progresses however slow the machine is.
  std::atomic<int> ticks{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kTrackers; ++t) {
    logs[t].map = t % 2 == 0 ? "a" : "b";
    threads.emplace_back([&, t] {
      TrackerLog& log = logs[t];
      grpc::ClientContext context;
      Prepare(&context);
      auto stream = d.stub->Track(&context);
      const int start = 3 * t;
      int after_done = 0;
      int last_tick = 0;
      for (int i = 0; i < 400 && after_done < 2; ++i) {
        if (i > 0) {
          while (!mapping_done.load() && ticks.load() <= last_tick) {
            absl::SleepFor(absl::Milliseconds(2));
          }
          last_tick = ticks.load();
        }
        pb::TrackRequest request;
        if (i == 0) {
          request.set_map(log.map);
          *request.mutable_options() = FastTrackOptions(512);
          *request.mutable_initial_pose() = ToProto(GroundTruth(PingPong(start)));
        }
        *request.mutable_frame() = EncodeFrame(PingPong(start + i), false);
        request.mutable_frame()->set_timestamp(i / 30.0);
        // Read before writing the check: frames sent after the job ended see its last version.
        const bool done = mapping_done.load();
        if (!stream->Write(request)) break;
        ++log.sent;
        pb::PoseEstimate estimate;
        if (!stream->Read(&estimate)) break;
        log.estimates.push_back(estimate);
        if (i == 0) ++first_estimates;
        if (done) ++after_done;
      }
      stream->WritesDone();
      pb::PoseEstimate extra;
      while (stream->Read(&extra)) log.estimates.push_back(extra);
      log.status = stream->Finish();
    });
  }
  // Whatever happens below (ASSERTs return early), the trackers stop and are joined.
  struct JoinAtExit {
    std::atomic<bool>* stop;
    std::vector<std::thread>* threads;
    ~JoinAtExit() {
      *stop = true;
      for (std::thread& t : *threads) {
        if (t.joinable()) t.join();
      }
    }
  } join_at_exit{&mapping_done, &threads};
  ASSERT_TRUE(WaitFor([&] { return first_estimates.load() == kTrackers; }))
      << "not every tracker got its first estimate";

  // The mapping job on "a", watched from its own thread.
  std::mutex watch_mutex;
  std::vector<pb::JobStatus> job_statuses;
  grpc::Status watch_status;
  std::vector<std::thread> watcher_thread;
  JoinAtExit join_watcher{&mapping_done, &watcher_thread};
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Integrate(&context);
  pb::IntegrateRequest first;
  first.set_map("a");
  pb::IntegrateOptions options = SmallIntegrateOptions();
  options.set_iterations_per_keyframe(20);
  *first.mutable_options() = options;
  ASSERT_TRUE(stream->Write(first));
  for (int index : {5, 15, 25}) {
    pb::IntegrateRequest request;
    *request.mutable_frame() = EncodeFrame(index, true);
    ASSERT_TRUE(stream->Write(request));
  }
  std::vector<pb::MappingProgress> progress(1);
  ASSERT_TRUE(stream->Read(&progress[0]));
  ++ticks;
  const std::string job_id = progress[0].job_id();
  ASSERT_FALSE(job_id.empty());
  watcher_thread.emplace_back([&] {
    grpc::ClientContext watch_context;
    Prepare(&watch_context);
    pb::WatchJobRequest request;
    request.set_job_id(job_id);
    auto reader = d.stub->WatchJob(&watch_context, request);
    pb::JobStatus status;
    while (reader->Read(&status)) {
      std::lock_guard<std::mutex> lock(watch_mutex);
      job_statuses.push_back(status);
    }
    std::lock_guard<std::mutex> lock(watch_mutex);
    watch_status = reader->Finish();
  });
  // The job cannot end before the client half-closes: wait for the watcher's first status.
  EXPECT_TRUE(WaitFor([&] {
    std::lock_guard<std::mutex> lock(watch_mutex);
    return !job_statuses.empty();
  }));
  pb::MapInfo during;
  ASSERT_TRUE(GetMap(*d.stub, "a", &during).ok());
  EXPECT_TRUE(during.mapping());
  stream->WritesDone();
  pb::MappingProgress p;
  while (stream->Read(&p)) {
    progress.push_back(p);
    ++ticks;
  }
  const grpc::Status integrated = stream->Finish();
  mapping_done = true;
  for (std::thread& t : watcher_thread) t.join();
  for (std::thread& t : threads) t.join();

  ASSERT_TRUE(integrated.ok()) << Describe(integrated);
  ASSERT_TRUE(progress.back().done());
  EXPECT_EQ(progress.back().keyframes_integrated(), 3u);
  pb::MapInfo a_after, b_after;
  ASSERT_TRUE(GetMap(*d.stub, "a", &a_after).ok());
  ASSERT_TRUE(GetMap(*d.stub, "b", &b_after).ok());
  EXPECT_GT(a_after.version(), a_before.version());
  EXPECT_EQ(a_after.version(), progress.back().map_version());
  EXPECT_FALSE(a_after.mapping());
  EXPECT_EQ(b_after.version(), b_before.version());

  // WatchJob: RUNNING first, DONE last, nothing else in between.
  EXPECT_TRUE(watch_status.ok()) << Describe(watch_status);
  ASSERT_FALSE(job_statuses.empty());
  EXPECT_EQ(job_statuses.front().state(), pb::JobStatus::STATE_RUNNING);
  EXPECT_EQ(job_statuses.back().state(), pb::JobStatus::STATE_DONE)
      << job_statuses.back().message();
  for (const pb::JobStatus& s : job_statuses) {
    EXPECT_TRUE(s.state() == pb::JobStatus::STATE_RUNNING || s.state() == pb::JobStatus::STATE_DONE)
        << s.state();
    EXPECT_EQ(s.job_id(), job_id);
    EXPECT_EQ(s.map(), "a");
  }

  for (int t = 0; t < kTrackers; ++t) {
    const TrackerLog& log = logs[t];
    SCOPED_TRACE("tracker " + std::to_string(t) + " on map " + log.map);
    EXPECT_TRUE(log.status.ok()) << Describe(log.status);
    EXPECT_GE(log.sent, 3);
    EXPECT_EQ(static_cast<int>(log.estimates.size()), log.sent) << "an estimate is missing";
    uint64_t previous = 0;
    int lost = 0;
    for (const pb::PoseEstimate& e : log.estimates) {
      EXPECT_EQ(e.dropped(), 0u);
      EXPECT_GE(e.map_version(), previous) << "the map version went backwards";
      previous = e.map_version();
      lost += e.state() == pb::TRACKING_STATE_LOST;
    }
    EXPECT_EQ(lost, 0);
    if (log.map == "a") {
      EXPECT_EQ(log.estimates.front().map_version(), a_before.version());
      EXPECT_EQ(log.estimates.back().map_version(), a_after.version());
    } else {
      EXPECT_EQ(log.estimates.front().map_version(), b_before.version());
      EXPECT_EQ(log.estimates.back().map_version(), b_before.version());
    }
  }
}

// TrackRequest.initial_pose is "the pose to start from"; a first message that names the map and
// carries initial_pose but no frame yet must still start the stream there.
TEST(StreamsTest, InitialPoseInAFramelessFirstMessageIsUsed) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Track(&context);
  pb::TrackRequest first;
  first.set_map("room");
  *first.mutable_options() = FastTrackOptions();
  *first.mutable_initial_pose() = ToProto(GroundTruth(5));
  ASSERT_TRUE(stream->Write(first));
  std::vector<pb::PoseEstimate> estimates;
  for (int i = 5; i < 8; ++i) {
    pb::TrackRequest r;
    *r.mutable_frame() = EncodeFrame(i, false);
    ASSERT_TRUE(stream->Write(r));
    pb::PoseEstimate e;
    ASSERT_TRUE(stream->Read(&e));
    estimates.push_back(e);
  }
  stream->WritesDone();
  ASSERT_TRUE(stream->Finish().ok());
  const double start_error =
      (FromProto(estimates[0].pose()).translation() - GroundTruth(5).translation()).norm();
  EXPECT_LT(start_error, 1e-9) << "the first estimate is not the initial pose ("
                               << estimates[0].reason() << ")";
  for (const pb::PoseEstimate& e : estimates) {
    EXPECT_EQ(e.state(), pb::TRACKING_STATE_OK) << e.reason();
  }
  EXPECT_LT(TranslationRmse(estimates, {5, 6, 7}), 0.01);
}

// A burst of 20 frames written without waiting: the tracker keeps only the newest waiting
// frame, so fewer than 20 estimates come back, and every frame is either estimated or counted
// in some estimate's `dropped`. The newest frame is always served.
TEST(StreamsTest, LatestWinsDropsAndCountsFrames) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;

  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Track(&context);
  // The stream's start (served at once: it only sets the pose), then the burst.
  pb::TrackRequest request;
  request.set_map("room");
  *request.mutable_options() = FastTrackOptions(4096);
  *request.mutable_initial_pose() = ToProto(GroundTruth(0));
  *request.mutable_frame() = EncodeFrame(0, false);
  ASSERT_TRUE(stream->Write(request));
  pb::PoseEstimate start;
  ASSERT_TRUE(stream->Read(&start));
  EXPECT_EQ(start.dropped(), 0u);

  constexpr int kBurst = 20;
  for (int i = 1; i <= kBurst; ++i) {
    pb::TrackRequest next;
    *next.mutable_frame() = EncodeFrame(i, false);
    ASSERT_TRUE(stream->Write(next)) << i;
  }
  stream->WritesDone();
  std::vector<pb::PoseEstimate> estimates;
  pb::PoseEstimate e;
  while (stream->Read(&e)) estimates.push_back(e);
  const grpc::Status status = stream->Finish();
  ASSERT_TRUE(status.ok()) << Describe(status);

  ASSERT_FALSE(estimates.empty());
  EXPECT_LT(static_cast<int>(estimates.size()), kBurst);
  int dropped = 0;
  double previous = 0.0;
  for (const pb::PoseEstimate& x : estimates) {
    dropped += static_cast<int>(x.dropped());
    EXPECT_GT(x.timestamp(), previous) << "estimates out of order";
    previous = x.timestamp();
  }
  EXPECT_GT(dropped, 0);
  EXPECT_EQ(dropped + static_cast<int>(estimates.size()), kBurst);
  EXPECT_DOUBLE_EQ(estimates.back().timestamp(), Room().frames()[kBurst].timestamp);
}

// Clients cancel a Track and an Integrate stream mid-way: both end CANCELLED, the job reads
// CANCELLED, the writer lease comes back (a new Integrate on the map succeeds), every stream
// slot is returned, and the other map serves exactly as before.
TEST(StreamsTest, ClientCancellationReleasesTheLeaseAndLeavesOthersAlone) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"a", "b"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::RenderResponse b_before;
  ASSERT_TRUE(Render(*d.stub, RenderRequestAt("b", 10), &b_before).ok());

  // Track: three frames, then cancel with the stream open.
  {
    grpc::ClientContext context;
    Prepare(&context);
    auto stream = d.stub->Track(&context);
    for (int i = 0; i < 3; ++i) {
      pb::TrackRequest request;
      if (i == 0) {
        request.set_map("a");
        *request.mutable_options() = FastTrackOptions();
        *request.mutable_initial_pose() = ToProto(GroundTruth(0));
      }
      *request.mutable_frame() = EncodeFrame(i, false);
      ASSERT_TRUE(stream->Write(request));
      pb::PoseEstimate estimate;
      ASSERT_TRUE(stream->Read(&estimate));
    }
    // One more frame in flight when the cancel comes.
    pb::TrackRequest request;
    *request.mutable_frame() = EncodeFrame(3, false);
    stream->Write(request);
    context.TryCancel();
    pb::PoseEstimate estimate;
    while (stream->Read(&estimate)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }

  // Integrate: the job is running (lease held) when the client cancels.
  std::string job_id;
  {
    grpc::ClientContext context;
    Prepare(&context);
    auto stream = d.stub->Integrate(&context);
    pb::IntegrateRequest first;
    first.set_map("a");
    *first.mutable_options() = SmallIntegrateOptions();
    *first.mutable_frame() = EncodeFrame(5, true);
    ASSERT_TRUE(stream->Write(first));
    pb::IntegrateRequest second;
    *second.mutable_frame() = EncodeFrame(15, true);
    ASSERT_TRUE(stream->Write(second));
    pb::MappingProgress progress;
    ASSERT_TRUE(stream->Read(&progress));
    job_id = progress.job_id();
    pb::MapInfo info;
    ASSERT_TRUE(GetMap(*d.stub, "a", &info).ok());
    EXPECT_TRUE(info.mapping());
    context.TryCancel();
    while (stream->Read(&progress)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }

  // The lease is released (asynchronously: the daemon learns of the cancel a moment later).
  EXPECT_TRUE(WaitFor([&] {
    pb::MapInfo info;
    return GetMap(*d.stub, "a", &info).ok() && !info.mapping();
  })) << "map \"a\" still has a mapping job after its client cancelled";
  EXPECT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 0; }))
      << "stream slots leaked: " << d.daemon->state().metrics->active_streams.load();
  {
    grpc::ClientContext context;
    Prepare(&context);
    pb::WatchJobRequest request;
    request.set_job_id(job_id);
    auto reader = d.stub->WatchJob(&context, request);
    pb::JobStatus status, last;
    while (reader->Read(&status)) last = status;
    EXPECT_TRUE(reader->Finish().ok());
    EXPECT_EQ(last.state(), pb::JobStatus::STATE_CANCELLED) << last.message();
  }
  const IntegrateResult again = Integrate(*d.stub, "a", {25});
  EXPECT_TRUE(again.status.ok()) << Describe(again.status);
  ASSERT_FALSE(again.progress.empty());
  EXPECT_TRUE(again.progress.back().done());

  // The daemon is healthy and "b" is untouched.
  EXPECT_EQ(HealthCheck(*d.health), kServing);
  pb::RenderResponse b_after;
  ASSERT_TRUE(Render(*d.stub, RenderRequestAt("b", 10), &b_after).ok());
  EXPECT_EQ(b_after.map_version(), b_before.map_version());
  EXPECT_EQ(b_after.color(), b_before.color());
  EXPECT_EQ(b_after.depth(), b_before.depth());
  const TrackResult tracked = TrackLockStep(*d.stub, "b", {0, 1, 2, 3});
  EXPECT_TRUE(tracked.status.ok()) << Describe(tracked.status);
  EXPECT_EQ(tracked.estimates.size(), 4u);
}

// WatchJob streams that clients cancel while the job they watch keeps reporting progress.
TEST(StreamsTest, WatchJobCancelledDuringUpdatesIsSafe) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartTestDaemon(TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_watch")));
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  ASSERT_TRUE(CreateMap(*d.stub, "m").ok());

  // A job that reports progress every few milliseconds for as long as it runs.
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Integrate(&context);
  pb::IntegrateRequest first;
  first.set_map("m");
  first.mutable_options()->set_iterations_per_keyframe(100000);
  first.mutable_options()->set_rays_per_iteration(64);
  *first.mutable_frame() = EncodeFrame(0, true);
  ASSERT_TRUE(stream->Write(first));
  pb::MappingProgress progress;
  ASSERT_TRUE(stream->Read(&progress));
  const std::string job_id = progress.job_id();
  std::thread drain_progress([&] {
    pb::MappingProgress p;
    while (stream->Read(&p)) {
    }
  });

  int cycles = 0;
  const absl::Time end = absl::Now() + absl::Seconds(5);
  while (absl::Now() < end) {
    grpc::ClientContext watch_context;
    Prepare(&watch_context);
    pb::WatchJobRequest request;
    request.set_job_id(job_id);
    auto reader = d.stub->WatchJob(&watch_context, request);
    pb::JobStatus status;
    const bool got_status = reader->Read(&status);
    if (got_status) {
      EXPECT_EQ(status.state(), pb::JobStatus::STATE_RUNNING);
      watch_context.TryCancel();
      while (reader->Read(&status)) {
      }
    }
    const grpc::Status finished = reader->Finish();
    if (got_status) {
      ++cycles;
    } else {
      // On a loaded machine the cancelled streams' cleanup can lag behind this loop and hold
      // every stream slot for a moment; the daemon then refuses, which is correct.
      EXPECT_EQ(finished.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(finished);
    }
  }
  context.TryCancel();
  drain_progress.join();
  EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_GT(cycles, 100);
  EXPECT_EQ(HealthCheck(*d.health), kServing);
}

}  // namespace
}  // namespace plx::server::testing

// The daemon's compute devices: --backend / --gpus parsing (app/make_backend.h), which workers
// Daemon::Start makes (one CPU worker without a GPU, a clear error for --backend cuda without
// one), how the worker pool spreads streams and one-off tasks, and where the devices are
// reported: Prometheus metrics and GetServerInfo.
#include <algorithm>
#include <condition_variable>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/make_backend.h"
#include "core/common/thread_priority.h"
#include "core/cpu/cpu_backend.h"
#include "server/device_worker.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

using ::testing::HasSubstr;

// ---------------------------------------------------------------------------------------------
// Parsing.

TEST(BackendFlagParseTest, BackendKinds) {
  EXPECT_EQ(*ParseBackendKind("cpu"), BackendKind::kCpu);
  EXPECT_EQ(*ParseBackendKind("cuda"), BackendKind::kCuda);
  EXPECT_EQ(*ParseBackendKind("auto"), BackendKind::kAuto);
  for (const char* bad : {"", "gpu", "CPU", "cuda:0"}) {
    const absl::StatusOr<BackendKind> kind = ParseBackendKind(bad);
    ASSERT_FALSE(kind.ok()) << bad;
    EXPECT_EQ(kind.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(kind.status().message(), HasSubstr("--backend must be cpu, cuda or auto"));
  }
}

TEST(BackendFlagParseTest, GpuListSyntaxErrorsNameTheFlag) {
  for (const char* bad : {"", "x", "0,", ",1", "-1", "0;1", "1.5", "all,0"}) {
    const absl::StatusOr<std::vector<int>> gpus = ParseGpuList(bad);
    ASSERT_FALSE(gpus.ok()) << "\"" << bad << "\"";
    EXPECT_EQ(gpus.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_THAT(gpus.status().message(), HasSubstr("--gpus")) << bad;
  }
}

TEST(BackendFlagParseTest, GpuListIdsMustExistOnce) {
  const int visible = CudaDeviceCount();
  const absl::StatusOr<std::vector<int>> all = ParseGpuList("all");
  ASSERT_TRUE(all.ok()) << all.status();
  EXPECT_EQ(static_cast<int>(all->size()), visible);
  const absl::StatusOr<std::vector<int>> missing = ParseGpuList(std::to_string(visible));
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.status().message(), HasSubstr("does not exist"));
  if (visible == 0) return;
  const absl::StatusOr<std::vector<int>> first = ParseGpuList("0");
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(*first, std::vector<int>{0});
  const absl::StatusOr<std::vector<int>> twice = ParseGpuList("0,0");
  ASSERT_FALSE(twice.ok());
  EXPECT_THAT(twice.status().message(), HasSubstr("listed twice"));
}

// ---------------------------------------------------------------------------------------------
// Workers.

std::unique_ptr<DeviceWorker> CpuWorker(const std::string& id,
                                        WorkerRole role = WorkerRole::kAll, int nice = 0) {
  return std::make_unique<DeviceWorker>(MakeCpuBackend(1),
                                        DeviceDescription{id, "cpu", id, role, nice});
}

TEST(WorkerPoolTest, StreamsSpreadOverTheWorkersAndStayBound) {
  std::vector<std::unique_ptr<DeviceWorker>> workers;
  workers.push_back(CpuWorker("a"));
  workers.push_back(CpuWorker("b"));
  WorkerPool pool(std::move(workers));
  DeviceWorker& first = pool.AttachStream(Priority::kInteractive);
  DeviceWorker& second = pool.AttachStream(Priority::kBackground);
  EXPECT_NE(&first, &second) << "two streams on one worker while another is idle";
  EXPECT_EQ(first.streams(), 1);
  EXPECT_EQ(second.streams(), 1);
  DeviceWorker& third = pool.AttachStream(Priority::kInteractive);
  EXPECT_EQ(third.streams(), 2);
  pool.DetachStream(first);
  pool.DetachStream(second);
  pool.DetachStream(third);
  EXPECT_EQ(pool.worker(0).streams() + pool.worker(1).streams(), 0);
  pool.StopAll();
}

TEST(WorkerPoolTest, OneOffTasksGoToTheWorkerWithTheShortestQueue) {
  std::vector<std::unique_ptr<DeviceWorker>> workers;
  workers.push_back(CpuWorker("a"));
  workers.push_back(CpuWorker("b"));
  WorkerPool pool(std::move(workers));
  // Worker "a" is kept busy until released; Pick must then choose "b".
  std::mutex mutex;
  std::condition_variable cv;
  bool release = false, started = false;
  pool.worker(0).Post(Priority::kInteractive, [&](Backend*, bool) {
    std::unique_lock<std::mutex> lock(mutex);
    started = true;
    cv.notify_all();
    cv.wait(lock, [&] { return release; });
  });
  {
    std::unique_lock<std::mutex> lock(mutex);
    cv.wait(lock, [&] { return started; });
  }
  EXPECT_EQ(pool.worker(0).queue_depth(), 1);
  EXPECT_EQ(pool.Pick(Priority::kInteractive).device().id, "b");
  EXPECT_EQ(pool.total_queue_depth(), 1);
  {
    std::lock_guard<std::mutex> lock(mutex);
    release = true;
    cv.notify_all();
  }
  pool.StopAll();
}

// The CPU's split: tracking streams and renders on the interactive worker, mapping streams and
// exports on the mapping worker, however loaded the other one is.
TEST(WorkerPoolTest, WorkGoesToTheWorkersWhoseRoleTakesIt) {
  std::vector<std::unique_ptr<DeviceWorker>> workers;
  workers.push_back(CpuWorker("track", WorkerRole::kInteractive));
  workers.push_back(CpuWorker("map", WorkerRole::kMapping, 7));
  WorkerPool pool(std::move(workers));
  DeviceWorker& tracker1 = pool.AttachStream(Priority::kInteractive);
  DeviceWorker& tracker2 = pool.AttachStream(Priority::kInteractive);
  DeviceWorker& mapper = pool.AttachStream(Priority::kBackground);
  EXPECT_EQ(tracker1.device().id, "track");
  EXPECT_EQ(tracker2.device().id, "track") << "a tracking stream went to the mapping worker";
  EXPECT_EQ(mapper.device().id, "map");
  EXPECT_EQ(pool.Pick(Priority::kInteractive).device().id, "track");
  EXPECT_EQ(pool.Pick(Priority::kBackground).device().id, "map");
  // The mapping worker's thread runs its tasks at its lowered priority.
  std::promise<int> nice;
  pool.worker(1).Post(Priority::kBackground,
                      [&](Backend*, bool) { nice.set_value(CurrentThreadNice()); });
  EXPECT_EQ(nice.get_future().get(), std::min(19, CurrentThreadNice() + 7));
  pool.DetachStream(tracker1);
  pool.DetachStream(tracker2);
  pool.DetachStream(mapper);
  pool.StopAll();
}

// ---------------------------------------------------------------------------------------------
// Daemon::Start.

TEST(DaemonDevicesTest, CudaWithoutAGpuFailsAtStartNamingCuda) {
  if (CudaDeviceCount() > 0) GTEST_SKIP() << "a CUDA device is visible here";
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_cuda"));
  o.backend = BackendKind::kCuda;
  const absl::StatusOr<std::unique_ptr<Daemon>> d = Daemon::Start(o);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(d.status().message(), HasSubstr("--backend cuda: "));
  EXPECT_THAT(d.status().message(), HasSubstr("CUDA"));
}

TEST(DaemonDevicesTest, GpusWithTheCpuBackendIsInvalid) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_gpus"));
  o.backend = BackendKind::kCpu;
  o.gpus = std::vector<int>{0};
  const absl::StatusOr<std::unique_ptr<Daemon>> d = Daemon::Start(o);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(d.status().message(), HasSubstr("--gpus only applies"));
}

grpc::Status GetServerInfo(pb::Plenoxd::Stub& stub, pb::ServerInfo* info,
                           const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  return stub.GetServerInfo(&context, pb::GetServerInfoRequest(), info);
}

// auto without a GPU (and cpu anywhere): the CPU's interactive and mapping workers, reported by
// GetServerInfo and metrics.
TEST(DaemonDevicesTest, TheCpuWorkersAreReportedByGetServerInfoAndMetrics) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_devices"));
  o.metrics_port = 0;
  if (CudaDeviceCount() > 0) o.backend = BackendKind::kCpu;  // else the default, auto
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;

  pb::ServerInfo info;
  const grpc::Status s = GetServerInfo(*d.stub, &info);
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_EQ(info.version(), PlenoxdVersion());
  EXPECT_FALSE(info.version().empty());
  EXPECT_EQ(info.backend(), CudaDeviceCount() > 0 ? "cpu" : "auto");
  EXPECT_EQ(info.cuda_built(), BuiltWithCuda());
  EXPECT_EQ(info.maps(), 0u);
  ASSERT_EQ(info.devices_size(), 2);
  EXPECT_EQ(info.devices(0).id(), "cpu");
  EXPECT_EQ(info.devices(0).kind(), "cpu");
  EXPECT_EQ(info.devices(0).name(), "cpu (2 threads, interactive)");
  EXPECT_EQ(info.devices(0).queue_depth(), 0u);
  EXPECT_EQ(info.devices(0).streams(), 0u);
  EXPECT_EQ(info.devices(1).id(), "cpu-mapping");
  EXPECT_EQ(info.devices(1).kind(), "cpu");
  EXPECT_EQ(info.devices(1).name(), "cpu (2 threads, mapping, nice +10)");

  ASSERT_TRUE(CreateMap(*d.stub, "one").ok());
  ASSERT_TRUE(GetServerInfo(*d.stub, &info).ok());
  EXPECT_EQ(info.maps(), 1u);

  const std::string body = HttpGet(d.daemon->metrics_port(), "/metrics");
  ASSERT_EQ(body.rfind("HTTP/1.1 200", 0), 0u) << body.substr(0, 200);
  EXPECT_THAT(body, HasSubstr("# TYPE plenoxd_device_info gauge\n"));
  EXPECT_THAT(body, HasSubstr("plenoxd_device_info{device=\"cpu\",kind=\"cpu\","
                              "name=\"cpu (2 threads, interactive)\"} 1\n"));
  EXPECT_THAT(body, HasSubstr("# TYPE plenoxd_device_queue_depth gauge\n"
                              "plenoxd_device_queue_depth{device=\"cpu\"} 0\n"
                              "plenoxd_device_queue_depth{device=\"cpu-mapping\"} 0\n"));
  EXPECT_THAT(body, HasSubstr("# TYPE plenoxd_device_streams gauge\n"
                              "plenoxd_device_streams{device=\"cpu\"} 0\n"));
  EXPECT_THAT(body, HasSubstr("\nplenoxd_queue_depth 0\n"));
}

TEST(DaemonDevicesTest, GetServerInfoNeedsTheToken) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_info_auth"));
  o.auth_token = "s3cret";
  o.backend = BackendKind::kCpu;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  pb::ServerInfo info;
  EXPECT_EQ(GetServerInfo(*(*started)->stub, &info).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  const grpc::Status s = GetServerInfo(*(*started)->stub, &info, "s3cret");
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_EQ(info.backend(), "cpu");
  ASSERT_EQ(info.devices_size(), 2);
}

// --mapping-worker off: one CPU worker takes both kinds of work.
TEST(DaemonDevicesTest, WithoutTheMappingWorkerOneCpuWorkerDoesEverything) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_one_worker"));
  o.backend = BackendKind::kCpu;
  o.mapping_worker = false;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  pb::ServerInfo info;
  ASSERT_TRUE(GetServerInfo(*(*started)->stub, &info).ok());
  ASSERT_EQ(info.devices_size(), 1);
  EXPECT_EQ(info.devices(0).name(), "cpu (2 threads)");
}

TEST(DaemonDevicesTest, AMappingNiceOutsideItsRangeIsRefusedAtStart) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_bad_nice"));
  o.backend = BackendKind::kCpu;
  o.mapping_nice = 20;
  const absl::StatusOr<std::unique_ptr<Daemon>> d = Daemon::Start(o);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(d.status().message(), HasSubstr("--mapping-nice"));
}

// The metrics text escapes label values (a device name is free text).
TEST(MetricsDevicesTest, LabelValuesAreEscaped) {
  Metrics metrics;
  Metrics::Gauges g;
  g.devices.push_back({"cuda:0", "cuda", "odd \"name\" \\ here\nnext", 3, 2});
  const std::string text = metrics.Render(g);
  EXPECT_THAT(text, HasSubstr("plenoxd_device_info{device=\"cuda:0\",kind=\"cuda\","
                              "name=\"odd \\\"name\\\" \\\\ here\\nnext\"} 1\n"));
  EXPECT_THAT(text, HasSubstr("plenoxd_device_queue_depth{device=\"cuda:0\"} 3\n"));
  EXPECT_THAT(text, HasSubstr("plenoxd_device_streams{device=\"cuda:0\"} 2\n"));
}

TEST(MetricsRenderTest, LoopClosureGaugesAreWrittenAsGiven) {
  Metrics metrics;
  Metrics::Gauges g;
  g.slam_loops = 4;
  g.slam_loops_rejected = 2;
  g.slam_corrections = 1;
  g.slam_last_solve_s = 0.0125;
  const std::string text = metrics.Render(g);
  EXPECT_THAT(text, HasSubstr("plenoxd_slam_loops 4\n"));
  EXPECT_THAT(text, HasSubstr("plenoxd_slam_loops_rejected 2\n"));
  EXPECT_THAT(text, HasSubstr("plenoxd_slam_corrections 1\n"));
  EXPECT_THAT(text, HasSubstr("plenoxd_slam_last_solve_seconds 0.012500\n"));
}

}  // namespace
}  // namespace plx::server::testing

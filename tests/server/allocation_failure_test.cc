// Out of memory in one request fails that request with RESOURCE_EXHAUSTED and the daemon keeps
// serving the others. The failure is forced through the unified-memory hooks every large
// array of the engine is allocated with (core/common/unified_allocator.h).
#include <atomic>
#include <cstddef>
#include <limits>

#include <gtest/gtest.h>

#include "core/common/unified_allocator.h"
#include "core/grid/sparse_grid.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

// Allocations larger than the limit, or of exactly g_fail_size bytes (the hooks see the
// block's header too), fail; the default hooks serve the others.
std::atomic<size_t> g_fail_above{std::numeric_limits<size_t>::max()};
std::atomic<size_t> g_fail_size{0};

void* FailingAllocate(size_t bytes, void* context) {
  if (bytes > g_fail_above.load() || bytes == g_fail_size.load()) return nullptr;
  return DefaultUnifiedMemoryHooks().allocate(bytes, context);
}

void DefaultDeallocate(void* block, size_t bytes, void* context) {
  DefaultUnifiedMemoryHooks().deallocate(block, bytes, context);
}

const UnifiedMemoryHooks kFailingHooks{&FailingAllocate, &DefaultDeallocate, nullptr,
                                       "failing-test"};

// Installs failing hooks for the test's lifetime.
class AllocationFailureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    previous_ = InstallUnifiedMemoryHooks(&kFailingHooks);
  }
  void TearDown() override {
    g_fail_above = std::numeric_limits<size_t>::max();
    g_fail_size = 0;
    InstallUnifiedMemoryHooks(previous_);
  }
  const UnifiedMemoryHooks* previous_ = nullptr;
};

grpc::Status TrackOneFrame(TestDaemon& d, const std::string& map) {
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Track(&context);
  pb::TrackRequest request;
  request.set_map(map);
  *request.mutable_options() = FastTrackOptions();
  *request.mutable_initial_pose() = ToProto(GroundTruth(0));
  *request.mutable_frame() = EncodeFrame(0, false);
  stream->Write(request);
  stream->WritesDone();
  pb::PoseEstimate estimate;
  while (stream->Read(&estimate)) {
  }
  return stream->Finish();
}

grpc::Status IntegrateOneKeyframe(TestDaemon& d, const std::string& map) {
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Integrate(&context);
  pb::IntegrateRequest request;
  request.set_map(map);
  *request.mutable_options() = SmallIntegrateOptions();
  *request.mutable_frame() = EncodeFrame(0, true);
  stream->Write(request);
  stream->WritesDone();
  pb::MappingProgress progress;
  while (stream->Read(&progress)) {
  }
  return stream->Finish();
}

TEST_F(AllocationFailureTest, AFrameThatCannotBeDecodedFailsOnlyItsStream) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"a"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  // A frame's decoded images are the largest arrays of a Track request.
  g_fail_above = 16 * 1024;
  const grpc::Status failed = TrackOneFrame(d, "a");
  EXPECT_EQ(failed.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(failed);
  EXPECT_NE(failed.error_message().find("out of memory"), std::string::npos) << Describe(failed);

  g_fail_above = std::numeric_limits<size_t>::max();
  const grpc::Status ok = TrackOneFrame(d, "a");
  EXPECT_TRUE(ok.ok()) << Describe(ok);
  EXPECT_EQ(HealthCheck(*d.health), kServing);
}

TEST_F(AllocationFailureTest, BricksThatCannotBeAllocatedFailTheMappingJobOnly) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"a"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  ASSERT_TRUE(CreateMap(*d.stub, "fresh").ok());

  // Only a brick's parameter block (56 KB, plus the block header) fails: decoding succeeds and
  // the brick allocation is what runs out.
  g_fail_size = static_cast<size_t>(kBrickFloats) * sizeof(float) + kUnifiedAlignment;
  SparseGrid::ReleasePooledBricks();  // pooled blocks would not reach the allocator
  const grpc::Status failed = IntegrateOneKeyframe(d, "fresh");
  EXPECT_EQ(failed.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(failed);
  EXPECT_NE(failed.error_message().find("allocating bricks"), std::string::npos)
      << Describe(failed);

  g_fail_size = 0;
  // The lease was released and the daemon maps and tracks again.
  const grpc::Status mapped = IntegrateOneKeyframe(d, "fresh");
  EXPECT_TRUE(mapped.ok()) << Describe(mapped);
  const grpc::Status tracked = TrackOneFrame(d, "a");
  EXPECT_TRUE(tracked.ok()) << Describe(tracked);
}

// The tracker's own buffers (not a backend call's) run out on the worker: the exception used to
// escape the worker's task and end the process; now it fails that stream only.
TEST_F(AllocationFailureTest, TrackerBuffersThatCannotBeAllocatedFailTheStreamOnly) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"a"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  // The tracker's sampled pixel ids: 1000 int32 (plus the block header), a size no decoded
  // image or power-of-two growth has.
  constexpr int kRays = 1000;
  g_fail_size = kRays * sizeof(int32_t) + kUnifiedAlignment;
  const TrackResult failed = TrackLockStep(*d.stub, "a", {0, 1}, FastTrackOptions(kRays));
  EXPECT_EQ(failed.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << Describe(failed.status);
  EXPECT_NE(failed.status.error_message().find("tracking a frame: out of memory"),
            std::string::npos)
      << Describe(failed.status);

  g_fail_size = 0;
  const TrackResult ok = TrackLockStep(*d.stub, "a", {0, 1}, FastTrackOptions(kRays));
  EXPECT_TRUE(ok.status.ok()) << Describe(ok.status);
  EXPECT_EQ(ok.estimates.size(), 2u);
  EXPECT_EQ(HealthCheck(*d.health), kServing);
}

}  // namespace
}  // namespace plx::server::testing

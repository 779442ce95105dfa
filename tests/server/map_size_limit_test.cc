// --max-map-mb holds before memory is spent, not only when a version is published: LoadMap
// refuses a file whose header says it is too large, and Integrate refuses a keyframe whose
// bricks would take the map over the limit, both before allocating a single brick (an audit saw
// a 428 MB peak against a 20 MB limit). Brick allocations are counted through the unified
// memory hooks every brick comes from (core/common/unified_allocator.h).
#include <atomic>
#include <cstddef>

#include <gtest/gtest.h>

#include "core/common/unified_allocator.h"
#include "core/grid/sparse_grid.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

// The hooks see a brick's parameter block plus the block header.
constexpr size_t kBrickBlockBytes = static_cast<size_t>(kBrickFloats) * sizeof(float) +
                                    kUnifiedAlignment;
std::atomic<int64_t> g_brick_blocks{0};

void* CountingAllocate(size_t bytes, void* context) {
  if (bytes == kBrickBlockBytes) g_brick_blocks++;
  return DefaultUnifiedMemoryHooks().allocate(bytes, context);
}
void CountingDeallocate(void* block, size_t bytes, void* context) {
  DefaultUnifiedMemoryHooks().deallocate(block, bytes, context);
}
const UnifiedMemoryHooks kCountingHooks{&CountingAllocate, &CountingDeallocate, nullptr,
                                        "counting-test"};

class MapSizeLimitTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Pooled blocks would be handed out without reaching the hooks.
    SparseGrid::ReleasePooledBricks();
    previous_ = InstallUnifiedMemoryHooks(&kCountingHooks);
    g_brick_blocks = 0;
  }
  void TearDown() override { InstallUnifiedMemoryHooks(previous_); }
  const UnifiedMemoryHooks* previous_ = nullptr;
};

TEST_F(MapSizeLimitTest, LoadMapOverTheLimitIsRefusedBeforeAllocating) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_loadlimit"));
  o.max_map_bytes = 1 << 20;  // the room map is tens of MB
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::MapInfo info;
  EXPECT_EQ(GetMap(*d.stub, "room", &info).error_code(), grpc::StatusCode::NOT_FOUND)
      << "loaded at start despite the limit";
  g_brick_blocks = 0;  // building the cached room map (SeedMaps) allocated bricks

  grpc::ClientContext context;
  Prepare(&context);
  pb::LoadMapRequest request;
  request.set_name("room");
  const grpc::Status s = d.stub->LoadMap(&context, request, &info);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  EXPECT_NE(s.error_message().find("over the limit of 1 MB per map"), std::string::npos)
      << Describe(s);
  EXPECT_EQ(g_brick_blocks.load(), 0);
}

TEST_F(MapSizeLimitTest, AKeyframeOverTheLimitIsRefusedBeforeAllocating) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_keylimit"));
  o.max_map_bytes = 1 << 20;  // a room keyframe adds about a hundred 56 KB bricks
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  ASSERT_TRUE(CreateMap(*d.stub, "small").ok());
  const IntegrateResult r = Integrate(*d.stub, "small", {0});
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(r.status);
  EXPECT_NE(r.status.error_message().find("nothing was allocated"), std::string::npos)
      << Describe(r.status);
  EXPECT_EQ(g_brick_blocks.load(), 0);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap(*d.stub, "small", &info).ok());
  EXPECT_EQ(info.bricks(), 0u);
  EXPECT_FALSE(info.mapping());
}

}  // namespace
}  // namespace plx::server::testing

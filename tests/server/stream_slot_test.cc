// Admission of every streaming call without a daemon: --max-streams slots are counted in
// metrics->active_streams, a refused call takes none, and a slot goes back exactly once however
// its stream ends (Release, or the reactor deleted).
#include "server/stream_slot.h"

#include <memory>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "server/metrics.h"

namespace plx::server {
namespace {

using ::testing::HasSubstr;

class StreamSlotTest : public ::testing::Test {
 protected:
  StreamSlotTest() {
    state_.metrics = &metrics_;
    state_.config.max_streams = 2;
  }
  int64_t active() const { return metrics_.active_streams.load(); }

  Metrics metrics_;
  DaemonState state_;
  grpc::CallbackServerContext context_;  // not started: no metadata, never cancelled
};

TEST_F(StreamSlotTest, TheLimitRefusesAndAReleasedSlotIsFreeAgain) {
  StreamSlot a, b, c;
  ASSERT_TRUE(a.Acquire(state_, &context_).ok());
  ASSERT_TRUE(b.Acquire(state_, &context_).ok());
  EXPECT_EQ(active(), 2);
  const absl::Status refused = c.Acquire(state_, &context_);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_THAT(refused.message(), HasSubstr("too many open streams (limit 2)"));
  EXPECT_FALSE(c.held());
  EXPECT_EQ(active(), 2) << "a refused stream takes no slot";

  a.Release();
  a.Release();  // once only
  EXPECT_FALSE(a.held());
  EXPECT_EQ(active(), 1);
  EXPECT_TRUE(c.Acquire(state_, &context_).ok());
  EXPECT_TRUE(c.held());
  EXPECT_EQ(active(), 2);
}

TEST_F(StreamSlotTest, ASlotGoesBackWithItsOwner) {
  {
    auto held = std::make_unique<StreamSlot>();
    ASSERT_TRUE(held->Acquire(state_, &context_).ok());
    StreamSlot refused_owner;
    state_.config.max_streams = 1;
    EXPECT_FALSE(refused_owner.Acquire(state_, &context_).ok());
    EXPECT_EQ(active(), 1);
    held.reset();
    EXPECT_EQ(active(), 0);
    // Released then destroyed: still counted once.
    StreamSlot released;
    ASSERT_TRUE(released.Acquire(state_, &context_).ok());
    released.Release();
    EXPECT_EQ(active(), 0);
  }
  EXPECT_EQ(active(), 0);
}

TEST_F(StreamSlotTest, ADrainingDaemonAdmitsNoStream) {
  state_.draining = true;
  StreamSlot slot;
  const absl::Status s = slot.Acquire(state_, &context_);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_FALSE(slot.held());
  EXPECT_EQ(active(), 0);
}

// With --auth-token, a call without the bearer token is refused before it counts (the token
// itself is checked by CheckCall; tests/server/auth_drain_test.cc sends real headers).
TEST_F(StreamSlotTest, WithoutCredentialsNoSlotIsTaken) {
  state_.config.auth_token = "secret";
  StreamSlot slot;
  EXPECT_EQ(slot.Acquire(state_, &context_).code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(active(), 0);
}

}  // namespace
}  // namespace plx::server

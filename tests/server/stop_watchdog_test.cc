// The stop watchdog (server/stop_watchdog.h) in-process: it fires after its limit unless
// disarmed, names the unsaved maps, and never hangs itself on a busy map store. How plenoxd
// itself stops on SIGTERM is in stop_test.cc.
#include "server/stop_watchdog.h"

#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

TEST(StopWatchdogTest, ExpiresAfterItsLimitNamingTheUnsavedMaps) {
  std::atomic<bool> expired{false};
  ::testing::internal::CaptureStderr();
  {
    StopWatchdog watchdog(absl::Milliseconds(50),
                          [] { return std::vector<std::string>{"kitchen", "hall"}; },
                          [&] { expired = true; });
    EXPECT_TRUE(WaitFor([&] { return expired.load(); }));
  }
  const std::string log = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(log.find("event=stop_timeout"), std::string::npos) << log;
  EXPECT_NE(log.find("unsaved_maps=kitchen,hall"), std::string::npos) << log;
  EXPECT_NE(log.find("event=map_not_saved map=kitchen"), std::string::npos) << log;
  EXPECT_NE(log.find("event=map_not_saved map=hall"), std::string::npos) << log;
}

TEST(StopWatchdogTest, DisarmedInTimeItDoesNothing) {
  std::atomic<bool> expired{false};
  {
    StopWatchdog watchdog(absl::Milliseconds(300), [] { return std::vector<std::string>{}; },
                          [&] { expired = true; });
    watchdog.Disarm();
    std::this_thread::sleep_for(std::chrono::milliseconds(600));
  }
  EXPECT_FALSE(expired.load());
}

// A map store whose lock a stuck thread holds must not keep the process alive.
TEST(StopWatchdogTest, ExpiresEvenWhenTheUnsavedMapsCannotBeNamed) {
  std::atomic<bool> expired{false};
  // Static: the watchdog's helper thread may look at it after this test returned.
  static std::atomic<bool> release{false};
  ::testing::internal::CaptureStderr();
  {
    StopWatchdog watchdog(
        absl::Milliseconds(50),
        [] {
          while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(5));
          return std::vector<std::string>{"late"};
        },
        [&] { expired = true; });
    EXPECT_TRUE(WaitFor([&] { return expired.load(); }));
    release = true;
  }
  const std::string log = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(log.find("unsaved_maps=\"unknown (map store busy)\""), std::string::npos) << log;
}

}  // namespace
}  // namespace plx::server::testing

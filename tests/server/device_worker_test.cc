// The device worker's scheduling: interactive work first, background work never starved.
#include "server/device_worker.h"

#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace plx::server {
namespace {

DeviceDescription Io() { return {"io", "io", "test worker"}; }

// With the worker busy, a background task queued before an interactive one still runs after it.
TEST(DeviceWorkerTest, InteractiveRunsBeforeQueuedBackground) {
  DeviceWorker worker(nullptr, Io());
  std::promise<void> gate;
  std::shared_future<void> open = gate.get_future().share();
  std::mutex mutex;
  std::vector<std::string> order;
  std::promise<void> both_ran;
  worker.Post(Priority::kInteractive, [open](Backend*, bool) { open.wait(); });
  worker.Post(Priority::kBackground, [&](Backend*, bool) {
    std::lock_guard<std::mutex> lock(mutex);
    order.push_back("background");
    if (order.size() == 2) both_ran.set_value();
  });
  worker.Post(Priority::kInteractive, [&](Backend*, bool) {
    std::lock_guard<std::mutex> lock(mutex);
    order.push_back("interactive");
    if (order.size() == 2) both_ran.set_value();
  });
  gate.set_value();
  both_ran.get_future().wait();
  EXPECT_EQ(order, (std::vector<std::string>{"interactive", "background"}));
}

// Interactive tasks that keep re-posting themselves (a tracking load that never lets the queue
// empty) do not starve a background task: it runs after about 250 ms of waiting. Without the
// rule it would never run, so a 10 s bound cannot pass by accident.
TEST(DeviceWorkerTest, BackgroundIsNotStarvedByAContinuousInteractiveLoad) {
  DeviceWorker worker(nullptr, Io());
  std::atomic<bool> stop{false};
  std::atomic<int> interactive_runs{0};
  std::function<void(Backend*, bool)> busy = [&](Backend*, bool cancelled) {
    if (cancelled || stop) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    ++interactive_runs;
    worker.Post(Priority::kInteractive, busy);
  };
  worker.Post(Priority::kInteractive, busy);
  worker.Post(Priority::kInteractive, busy);  // two in the queue at all times
  std::promise<void> ran;
  worker.Post(Priority::kBackground, [&](Backend*, bool) { ran.set_value(); });
  const auto status = ran.get_future().wait_for(std::chrono::seconds(10));
  stop = true;
  EXPECT_EQ(status, std::future_status::ready) << "the background task never ran";
  EXPECT_GT(interactive_runs.load(), 10) << "interactive work ran first meanwhile";
  worker.Stop();
}

// Stop hands every queued task `cancelled` = true, so each can finish its RPC.
TEST(DeviceWorkerTest, StopCancelsQueuedTasks) {
  auto worker = std::make_unique<DeviceWorker>(nullptr, Io());
  std::promise<void> gate;
  std::shared_future<void> open = gate.get_future().share();
  std::promise<void> started;
  worker->Post(Priority::kInteractive, [&, open](Backend*, bool) {
    started.set_value();
    open.wait();
  });
  started.get_future().wait();
  std::atomic<int> cancelled{0}, ran{0};
  for (int i = 0; i < 3; ++i) {
    worker->Post(Priority::kBackground, [&](Backend*, bool c) { c ? ++cancelled : ++ran; });
  }
  std::thread releaser([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    gate.set_value();
  });
  worker->Stop();
  releaser.join();
  EXPECT_EQ(cancelled.load(), 3);
  EXPECT_EQ(ran.load(), 0);
}

}  // namespace
}  // namespace plx::server

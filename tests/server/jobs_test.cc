// The job registry behind WatchJob: jobs are named by kind and number, a finished job's status
// is final, and a watcher hears the status at once and after every change until it unwatches.
// After Unwatch returns its listener never runs again (WatchJobReactor deletes itself then).
#include "server/jobs.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace plx::server {
namespace {

TEST(JobRegistryTest, JobsAreNamedByKindAndStartQueued) {
  JobRegistry jobs;
  const std::string a = jobs.Create("integrate", "room");
  const std::string b = jobs.Create("slam", "hall");
  EXPECT_EQ(a, "integrate-1");
  EXPECT_EQ(b, "slam-2");

  absl::StatusOr<JobInfo> info = jobs.Get(b);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->id, b);
  EXPECT_EQ(info->kind, "slam");
  EXPECT_EQ(info->map, "hall");
  EXPECT_EQ(info->state, JobState::kQueued);
  EXPECT_EQ(info->progress, 0.0);
  EXPECT_FALSE(info->terminal());

  EXPECT_EQ(jobs.Get("integrate-3").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(jobs.Watch("nope", [](const JobInfo&) {}).status().code(), absl::StatusCode::kNotFound);
}

TEST(JobRegistryTest, AnEndedJobsStatusIsFinal) {
  JobRegistry jobs;
  const std::string done = jobs.Create("integrate", "room");
  const std::string failed = jobs.Create("integrate", "room");
  const std::string other = jobs.Create("integrate", "hall");
  jobs.Update(done, JobState::kRunning, 0.5, "half");
  jobs.Update(failed, JobState::kRunning, 0.1, "");
  jobs.Update(other, JobState::kRunning, 0.1, "");
  EXPECT_EQ(jobs.running(), 3);

  jobs.Update(done, JobState::kDone, 1.0, "published version 7");
  jobs.Update(failed, JobState::kFailed, 0.2, "out of memory");
  EXPECT_EQ(jobs.running(), 1);
  // A late update (e.g. a task that was still queued) does not bring an ended job back.
  jobs.Update(done, JobState::kRunning, 0.9, "late");
  jobs.Update(failed, JobState::kCancelled, 0.3, "late");
  jobs.Update("integrate-99", JobState::kRunning, 0.3, "unknown: ignored");
  EXPECT_EQ(jobs.running(), 1);

  absl::StatusOr<JobInfo> info = jobs.Get(done);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->state, JobState::kDone);
  EXPECT_EQ(info->progress, 1.0);
  EXPECT_EQ(info->message, "published version 7");
  EXPECT_TRUE(info->terminal());
  info = jobs.Get(failed);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->state, JobState::kFailed);
  EXPECT_EQ(info->message, "out of memory");
}

TEST(JobRegistryTest, AWatcherHearsTheStatusNowThenEachChangeOfItsJobOnly) {
  JobRegistry jobs;
  const std::string id = jobs.Create("integrate", "room");
  const std::string other = jobs.Create("integrate", "hall");
  jobs.Update(id, JobState::kRunning, 0.25, "waiting for keyframes");

  std::vector<JobInfo> heard;
  absl::StatusOr<int64_t> handle = jobs.Watch(id, [&](const JobInfo& info) {
    // Listeners run outside the registry's lock: calling back into it must not deadlock.
    EXPECT_TRUE(jobs.Get(info.id).ok());
    heard.push_back(info);
  });
  ASSERT_TRUE(handle.ok()) << handle.status();
  ASSERT_EQ(heard.size(), 1u);
  EXPECT_EQ(heard[0].state, JobState::kRunning);
  EXPECT_EQ(heard[0].progress, 0.25);
  EXPECT_EQ(heard[0].message, "waiting for keyframes");

  jobs.Update(other, JobState::kRunning, 0.5, "");
  jobs.Update(id, JobState::kRunning, 0.75, "optimising");
  jobs.Update(id, JobState::kDone, 1.0, "done");
  jobs.Update(id, JobState::kRunning, 0.1, "after the end: not heard");
  ASSERT_EQ(heard.size(), 3u);
  EXPECT_EQ(heard[1].progress, 0.75);
  EXPECT_EQ(heard[1].message, "optimising");
  EXPECT_EQ(heard[2].state, JobState::kDone);
  for (const JobInfo& info : heard) EXPECT_EQ(info.id, id);

  // A watcher of an ended job hears its final status once.
  std::vector<JobInfo> late;
  absl::StatusOr<int64_t> late_handle =
      jobs.Watch(id, [&](const JobInfo& info) { late.push_back(info); });
  ASSERT_TRUE(late_handle.ok());
  ASSERT_EQ(late.size(), 1u);
  EXPECT_EQ(late[0].state, JobState::kDone);
  EXPECT_NE(*late_handle, *handle);

  jobs.Unwatch(*handle);
  jobs.Unwatch(*late_handle);
  jobs.Unwatch(*handle);  // twice, or an unknown handle: nothing happens
  jobs.Unwatch(12345);
}

TEST(JobRegistryTest, UnwatchedListenersAreNotCalledAndMayUnwatchThemselves) {
  JobRegistry jobs;
  const std::string id = jobs.Create("integrate", "room");
  int gone_calls = 0;
  absl::StatusOr<int64_t> gone = jobs.Watch(id, [&](const JobInfo&) { ++gone_calls; });
  ASSERT_TRUE(gone.ok());
  jobs.Unwatch(*gone);

  // A listener that unwatches itself from inside its call (it must not wait for itself).
  int self_calls = 0;
  int64_t self = 0;
  absl::StatusOr<int64_t> handle = jobs.Watch(id, [&](const JobInfo& info) {
    ++self_calls;
    if (info.state == JobState::kRunning) jobs.Unwatch(self);
  });
  ASSERT_TRUE(handle.ok());
  self = *handle;
  jobs.Update(id, JobState::kRunning, 0.5, "");
  jobs.Update(id, JobState::kRunning, 0.6, "");
  jobs.Update(id, JobState::kDone, 1.0, "");

  EXPECT_EQ(gone_calls, 1);  // only Watch's own call
  EXPECT_EQ(self_calls, 2);  // Watch's call, then the update during which it unwatched
}

TEST(JobRegistryTest, UnwatchWaitsForAListenerCallAlreadyRunning) {
  JobRegistry jobs;
  const std::string id = jobs.Create("integrate", "room");
  std::mutex mutex;
  std::condition_variable changed;
  bool in_call = false;
  bool release = false;
  absl::StatusOr<int64_t> handle = jobs.Watch(id, [&](const JobInfo& info) {
    if (info.state != JobState::kRunning) return;
    std::unique_lock<std::mutex> lock(mutex);
    in_call = true;
    changed.notify_all();
    changed.wait(lock, [&] { return release; });
  });
  ASSERT_TRUE(handle.ok());

  std::thread updater([&] { jobs.Update(id, JobState::kRunning, 0.5, ""); });
  {
    std::unique_lock<std::mutex> lock(mutex);
    changed.wait(lock, [&] { return in_call; });
  }
  std::atomic<bool> unwatched{false};
  std::thread unwatcher([&] {
    jobs.Unwatch(*handle);
    unwatched = true;
  });
  // While the listener runs, Unwatch must not return: its owner would be deleted under it.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_FALSE(unwatched.load());
  {
    std::lock_guard<std::mutex> lock(mutex);
    release = true;
  }
  changed.notify_all();
  unwatcher.join();
  updater.join();
  EXPECT_TRUE(unwatched.load());
}

}  // namespace
}  // namespace plx::server

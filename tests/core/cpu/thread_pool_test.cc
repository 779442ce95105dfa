#include "core/cpu/thread_pool.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <mutex>
#include <numeric>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/thread_priority.h"
#include "core/cpu/parallel_for.h"

namespace plx::cpu {
namespace {

TEST(ThreadPoolTest, VisitsEveryIndexExactlyOnce) {
  ThreadPool pool(3);
  EXPECT_EQ(pool.num_threads(), 3);
  std::vector<std::atomic<int>> hits(100003);
  ExecContext ctx{&pool};
  ParallelFor(ctx, static_cast<int64_t>(hits.size()), [&](int64_t i) { hits[i].fetch_add(1); });
  for (const auto& h : hits) ASSERT_EQ(h.load(), 1);
}

// A background pool's workers run at the lowered priority; the calling thread keeps its own.
TEST(ThreadPoolTest, NiceLowersTheWorkersPriorityOnly) {
  const int caller = CurrentThreadNice();
  ThreadPool pool(3, 4);
  std::mutex mutex;
  std::vector<int> worker_nice, caller_nice;
  // One slow chunk per index, so every worker takes some.
  pool.ParallelForChunks(64, 1, [&](int64_t, int64_t) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    const int nice = CurrentThreadNice();
    std::lock_guard<std::mutex> lock(mutex);
    (ThreadPool::CurrentThreadIndex() == 0 ? caller_nice : worker_nice).push_back(nice);
  });
  ASSERT_FALSE(worker_nice.empty());
  for (int n : worker_nice) EXPECT_EQ(n, std::min(19, caller + 4));
  for (int n : caller_nice) EXPECT_EQ(n, caller);
  EXPECT_EQ(CurrentThreadNice(), caller);
}

TEST(ThreadPriorityTest, OutOfRangeIsRefusedAndZeroChangesNothing) {
  EXPECT_EQ(LowerCurrentThreadPriority(-1).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(LowerCurrentThreadPriority(20).code(), absl::StatusCode::kInvalidArgument);
  const int before = CurrentThreadNice();
  EXPECT_TRUE(LowerCurrentThreadPriority(0).ok());
  EXPECT_EQ(CurrentThreadNice(), before);
}

TEST(ThreadPoolTest, UsesSeveralThreadsAndRunsNestedLoopsSerially) {
  ThreadPool pool(2);
  std::atomic<int> max_index{0};
  std::atomic<int64_t> inner_sum{0};
  pool.ParallelForChunks(64, 1, [&](int64_t, int64_t) {
    // A slow chunk, so the worker takes some before the caller has done them all.
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    int idx = ThreadPool::CurrentThreadIndex();
    int prev = max_index.load();
    while (idx > prev && !max_index.compare_exchange_weak(prev, idx)) {
    }
    // A nested loop must not deadlock.
    pool.ParallelForChunks(10, 3, [&](int64_t b, int64_t e) { inner_sum += e - b; });
  });
  EXPECT_EQ(max_index.load(), 1) << "the pool's worker ran no chunk";
  EXPECT_EQ(inner_sum.load(), 640);
}

TEST(ThreadPoolTest, ManyConsecutiveLoops) {
  ThreadPool pool(2);
  int64_t total = 0;
  for (int loop = 0; loop < 500; ++loop) {
    std::atomic<int64_t> sum{0};
    pool.ParallelForChunks(1000, 7, [&](int64_t b, int64_t e) {
      int64_t s = 0;
      for (int64_t i = b; i < e; ++i) s += i;
      sum += s;
    });
    total += sum.load();
  }
  EXPECT_EQ(total, 500 * (999 * 1000 / 2));
}

TEST(ThreadPoolTest, EmptyAndSingleItemLoops) {
  ThreadPool pool(2);
  int calls = 0;
  pool.ParallelForChunks(0, 4, [&](int64_t, int64_t) { ++calls; });
  EXPECT_EQ(calls, 0);
  pool.ParallelForChunks(1, 4, [&](int64_t b, int64_t e) { calls += static_cast<int>(e - b); });
  EXPECT_EQ(calls, 1);
}

}  // namespace
}  // namespace plx::cpu

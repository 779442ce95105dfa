#include "core/cpu/thread_pool.h"

#include <algorithm>
#include <cstdlib>
#include <string>

#include "core/common/thread_priority.h"

namespace plx::cpu {
namespace {
thread_local int tls_thread_index = 0;
thread_local bool tls_inside_loop = false;
}  // namespace

ThreadPool::ThreadPool(int num_threads, int nice) {
  if (num_threads <= 0) num_threads = std::max(1u, std::thread::hardware_concurrency());
  for (int i = 1; i < num_threads; ++i) {
    workers_.emplace_back([this, i, nice] {
      // Best effort: a refused priority change leaves the worker at its creator's priority,
      // which only costs the interactive work some cycles.
      (void)LowerCurrentThreadPriority(nice);
      WorkerLoop(i);
    });
  }
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : workers_) t.join();
}

int ThreadPool::CurrentThreadIndex() { return tls_thread_index; }

void ThreadPool::RunChunks() {
  const bool was_inside = tls_inside_loop;
  tls_inside_loop = true;
  for (;;) {
    const int64_t begin = next_.fetch_add(grain_, std::memory_order_relaxed);
    if (begin >= n_) break;
    (*fn_)(begin, std::min(n_, begin + grain_));
  }
  tls_inside_loop = was_inside;
}

void ThreadPool::WorkerLoop(int index) {
  tls_thread_index = index;
  uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || generation_ != seen; });
      if (stopping_) return;
      seen = generation_;
    }
    RunChunks();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (--busy_workers_ == 0) done_.notify_one();
    }
  }
}

void ThreadPool::ParallelForChunks(int64_t n, int64_t grain,
                                   const std::function<void(int64_t, int64_t)>& fn) {
  if (n <= 0) return;
  grain = std::max<int64_t>(1, grain);
  if (workers_.empty() || tls_inside_loop || n <= grain) {
    for (int64_t b = 0; b < n; b += grain) fn(b, std::min(n, b + grain));
    return;
  }
  std::lock_guard<std::mutex> run_lock(run_mutex_);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fn_ = &fn;
    n_ = n;
    grain_ = grain;
    next_.store(0, std::memory_order_relaxed);
    busy_workers_ = static_cast<int>(workers_.size());
    ++generation_;
  }
  wake_.notify_all();
  const int saved_index = tls_thread_index;
  tls_thread_index = 0;
  RunChunks();
  tls_thread_index = saved_index;
  std::unique_lock<std::mutex> lock(mutex_);
  done_.wait(lock, [&] { return busy_workers_ == 0; });
  fn_ = nullptr;
}

ThreadPool& DefaultThreadPool() {
  static ThreadPool* pool = [] {
    int threads = 0;
    if (const char* env = std::getenv("PLX_NUM_THREADS")) threads = std::atoi(env);
    return new ThreadPool(threads);
  }();
  return *pool;
}

}  // namespace plx::cpu

// A fixed pool of worker threads that runs one data-parallel loop at a time; the CPU backend's
// ParallelFor sits on top of it. The calling thread works too, so a pool of N threads keeps
// N + 1 busy only when asked for more than the core count.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace plx::cpu {

class ThreadPool {
 public:
  // num_threads <= 0 means one per hardware thread. The pool starts num_threads - 1 workers.
  // `nice` (0-19) lowers the workers' CPU priority (core/common/thread_priority.h); the calling
  // thread, which works too, keeps its own: lower it as well for a pool of background work.
  explicit ThreadPool(int num_threads = 0, int nice = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int num_threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls fn(begin, end) over [0, n) in chunks of about `grain` items, on all threads; returns
  // when every chunk is done. Calls made from inside a running loop run serially.
  void ParallelForChunks(int64_t n, int64_t grain, const std::function<void(int64_t, int64_t)>& fn);

  // Index of the calling thread inside the current loop: 0 for the caller, 1.. for workers.
  static int CurrentThreadIndex();

 private:
  void WorkerLoop(int index);
  void RunChunks();

  std::vector<std::thread> workers_;
  std::mutex run_mutex_;  // one loop at a time
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  uint64_t generation_ = 0;
  bool stopping_ = false;
  int busy_workers_ = 0;

  // The loop being run.
  const std::function<void(int64_t, int64_t)>* fn_ = nullptr;
  int64_t n_ = 0;
  int64_t grain_ = 1;
  std::atomic<int64_t> next_{0};
};

// The process-wide pool used by the CPU backend (sized by $PLX_NUM_THREADS or the core count).
ThreadPool& DefaultThreadPool();

}  // namespace plx::cpu

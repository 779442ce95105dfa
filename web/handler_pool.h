// The side HTTP server's handler threads (web/http_server.h): a fixed number of threads and a
// bounded queue. TryRun refuses a task instead of queueing it without bound, so a flood of
// requests is answered "busy" at once rather than piling up work and memory.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace plx::web {

class HandlerPool {
 public:
  HandlerPool(int threads, int max_queued);
  // Drops the tasks that have not started and waits for the running ones.
  ~HandlerPool();
  HandlerPool(const HandlerPool&) = delete;
  HandlerPool& operator=(const HandlerPool&) = delete;

  // Queues `task` for the next free thread; false (and `task` not kept) when `max_queued` tasks
  // are already waiting.
  bool TryRun(std::function<void()> task);

 private:
  void Loop();

  const size_t max_queued_;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace plx::web

#include "server/device_worker.h"

#include <utility>

#include "core/common/thread_priority.h"

namespace plx::server {

DeviceWorker::DeviceWorker(std::unique_ptr<Backend> backend, DeviceDescription device)
    : backend_(std::move(backend)), device_(std::move(device)),
      thread_([this] { Loop(); }) {}

DeviceWorker::~DeviceWorker() { Stop(); }

void DeviceWorker::Post(Priority priority, DeviceTask task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stopping_) {
      queues_[static_cast<int>(priority)].push_back(
          {std::move(task), std::chrono::steady_clock::now()});
      wake_.notify_one();
      return;
    }
  }
  task(backend_.get(), true);  // stopped: tell the task it will not run
}

bool RoleTakes(WorkerRole role, Priority priority) {
  switch (role) {
    case WorkerRole::kAll:
      return true;
    case WorkerRole::kInteractive:
      return priority == Priority::kInteractive;
    case WorkerRole::kMapping:
      return priority == Priority::kBackground;
  }
  return false;
}

void DeviceWorker::Loop() {
  // Best effort: refused, the worker competes with the interactive one as an equal, which costs
  // tracking latency under load, not results.
  (void)LowerCurrentThreadPriority(device_.nice);
  for (;;) {
    DeviceTask task;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queues_[0].empty() || !queues_[1].empty(); });
      if (stopping_) return;
      // Interactive first, but a background task that has waited kBackgroundMaxWait runs next,
      // so a busy tracking load slows mapping down without stopping it.
      const bool background =
          queues_[0].empty() || (!queues_[1].empty() && std::chrono::steady_clock::now() -
                                                                queues_[1].front().queued >
                                                            kBackgroundMaxWait);
      std::deque<QueuedTask>& queue = background ? queues_[1] : queues_[0];
      task = std::move(queue.front().task);
      queue.pop_front();
      running_task_ = true;
    }
    task(backend_.get(), false);
    std::lock_guard<std::mutex> lock(mutex_);
    running_task_ = false;
  }
}

void DeviceWorker::Stop() {
  std::vector<DeviceTask> dropped;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& queue : queues_) {
      for (auto& queued : queue) dropped.push_back(std::move(queued.task));
      queue.clear();
    }
    wake_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
  for (auto& task : dropped) task(backend_.get(), true);
}

int DeviceWorker::queue_depth() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(queues_[0].size() + queues_[1].size()) + (running_task_ ? 1 : 0);
}

WorkerPool::WorkerPool(std::vector<std::unique_ptr<DeviceWorker>> workers)
    : workers_(std::move(workers)) {}

DeviceWorker& WorkerPool::Least(Priority work, bool by_streams_first) {
  // Each worker's load is read once: queues move while we look.
  DeviceWorker* best = nullptr;
  std::pair<int, int> best_load;
  for (const auto& w : workers_) {
    if (!RoleTakes(w->device().role, work)) continue;
    const std::pair<int, int> load =
        by_streams_first ? std::make_pair(w->streams(), w->queue_depth())
                         : std::make_pair(w->queue_depth(), w->streams());
    if (best == nullptr || load < best_load) {
      best = w.get();
      best_load = load;
    }
  }
  // No worker has the role (a pool set up without one): any worker can run any task.
  return best != nullptr ? *best : *workers_.front();
}

DeviceWorker& WorkerPool::Pick(Priority work) { return Least(work, /*by_streams_first=*/false); }

DeviceWorker& WorkerPool::AttachStream(Priority work) {
  std::lock_guard<std::mutex> lock(attach_mutex_);  // two streams starting at once spread out
  DeviceWorker& best = Least(work, /*by_streams_first=*/true);
  best.streams_.fetch_add(1, std::memory_order_relaxed);
  return best;
}

void WorkerPool::DetachStream(DeviceWorker& worker) {
  worker.streams_.fetch_sub(1, std::memory_order_relaxed);
}

void WorkerPool::StopAll() {
  for (auto& w : workers_) w->Stop();
}

int WorkerPool::total_queue_depth() const {
  int total = 0;
  for (const auto& w : workers_) total += w->queue_depth();
  return total;
}

std::vector<std::string> WorkerPool::device_names() const {
  std::vector<std::string> names;
  for (const auto& w : workers_) names.push_back(w->device_name());
  return names;
}

}  // namespace plx::server

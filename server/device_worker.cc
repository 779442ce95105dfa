#include "server/device_worker.h"

namespace plx::server {

DeviceWorker::DeviceWorker(std::unique_ptr<Backend> backend, std::string device_name)
    : backend_(std::move(backend)), device_name_(std::move(device_name)),
      thread_([this] { Loop(); }) {}

DeviceWorker::~DeviceWorker() { Stop(); }

void DeviceWorker::Post(Priority priority, DeviceTask task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stopping_) {
      queues_[static_cast<int>(priority)].push_back(std::move(task));
      wake_.notify_one();
      return;
    }
  }
  task(backend_.get(), true);  // stopped: tell the task it will not run
}

void DeviceWorker::Loop() {
  for (;;) {
    DeviceTask task;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queues_[0].empty() || !queues_[1].empty(); });
      if (stopping_) return;
      std::deque<DeviceTask>& queue = !queues_[0].empty() ? queues_[0] : queues_[1];
      task = std::move(queue.front());
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
      for (auto& task : queue) dropped.push_back(std::move(task));
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

DeviceWorker& WorkerPool::Pick() {
  DeviceWorker* best = workers_.front().get();
  for (const auto& w : workers_) {
    if (w->queue_depth() < best->queue_depth()) best = w.get();
  }
  return *best;
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

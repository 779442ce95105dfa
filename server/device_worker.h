// One worker thread per compute device (the CPU backend, or one per GPU later). Work is queued
// with a priority: interactive work (tracking, rendering) always runs before background work
// (mapping), and mapping is posted in short chunks, so a frame never waits behind a whole
// mapping pass, only behind the chunk in progress.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/kernels/backend.h"

namespace plx::server {

enum class Priority { kInteractive = 0, kBackground = 1 };

// A task gets the worker's backend (nullptr for a worker without one, e.g. file I/O) and
// `cancelled` = true when the worker stopped before running it: the task must then only clean
// up (e.g. finish its RPC as UNAVAILABLE).
using DeviceTask = std::function<void(Backend* backend, bool cancelled)>;

class DeviceWorker {
 public:
  DeviceWorker(std::unique_ptr<Backend> backend, std::string device_name);
  ~DeviceWorker();  // Stop()s

  void Post(Priority priority, DeviceTask task);
  // Runs the task in progress to its end, hands every queued task nullptr, joins the thread.
  void Stop();

  int queue_depth() const;
  const std::string& device_name() const { return device_name_; }

 private:
  void Loop();

  std::unique_ptr<Backend> backend_;
  std::string device_name_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<DeviceTask> queues_[2];
  bool stopping_ = false;
  bool running_task_ = false;
  std::thread thread_;
};

// The workers of the daemon; Post picks the one with the shortest queue.
class WorkerPool {
 public:
  explicit WorkerPool(std::vector<std::unique_ptr<DeviceWorker>> workers);
  DeviceWorker& Pick();
  void StopAll();
  int total_queue_depth() const;
  std::vector<std::string> device_names() const;

 private:
  std::vector<std::unique_ptr<DeviceWorker>> workers_;
};

}  // namespace plx::server

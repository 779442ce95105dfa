// One worker thread per compute device: the CPU backend (all its cores), or one per selected
// GPU, each owning its own Backend and its own queue. Work is queued with a priority:
// interactive work (tracking, rendering) runs before background work (mapping) unless mapping
// has waited 250 ms (so it slows down under a full tracking load but never stops), and
// mapping is posted in short chunks, so a frame never waits behind a whole mapping pass, only
// behind the chunk in progress on its device.
//
// On the CPU the daemon runs two workers by default (server/daemon.cc, --mapping-worker): one
// for interactive work and one for mapping (WorkerRole), each with a thread pool over all the
// cores, the mapping one at a lower OS priority (--mapping-nice). A tracking frame then never
// waits for the mapping chunk in progress (a teddy optimisation iteration is 0.3-0.5 s on 2
// cores): the kernel's scheduler shares the cores, the tracking threads first, and mapping
// takes every cycle tracking leaves. A GPU worker does both kinds (the device runs one kernel
// at a time anyway) and orders them by its queues.
//
// Streams (Track, Integrate) keep state made with one worker's backend (a Tracker, a Mapper),
// so a stream is bound to one worker for its whole life (WorkerPool::AttachStream); one-off
// calls (Render, Export) go to whichever worker is least busy (WorkerPool::Pick), each among
// the workers that do its kind of work.
//
// Despite the name, a DeviceWorker is a prioritised task thread that owns a backend only when
// it has one: the daemon also runs map saves and loads on a DeviceWorker with a null backend
// (kind "io", server/daemon.cc), kept out of the WorkerPool so disk waits never hold up a
// device.
#pragma once

#include <atomic>
#include <chrono>
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

// Which work a worker takes: both kinds (a GPU, or the one CPU worker with --mapping-worker
// off), or only one (the CPU's interactive and mapping workers).
enum class WorkerRole { kAll, kInteractive, kMapping };

// A task gets the worker's backend (nullptr for a worker without one, e.g. file I/O) and
// `cancelled` = true when the worker stopped before running it: the task must then only clean
// up (e.g. finish its RPC as UNAVAILABLE).
using DeviceTask = std::function<void(Backend* backend, bool cancelled)>;

// What a worker computes on, for logs, metrics and GetServerInfo.
struct DeviceDescription {
  std::string id;    // short and unique: "cpu", "cuda:0", "io"
  std::string kind;  // "cpu", "cuda", or "io" for the file worker without a backend
  std::string name;  // "cpu (16 threads)", "cuda:0 NVIDIA H100 80GB HBM3 (sm_90, 79.1 GiB)"
  WorkerRole role = WorkerRole::kAll;
  // Lowers the worker thread's OS priority by this many nice steps (0-19) when it starts; the
  // backend's own threads are lowered by the backend (MakeCpuBackend's `nice`).
  int nice = 0;
};

// Whether a worker of `role` takes work of `priority`.
bool RoleTakes(WorkerRole role, Priority priority);

class DeviceWorker {
 public:
  // `backend` may be null (the file-I/O worker): its tasks then get a null Backend*.
  DeviceWorker(std::unique_ptr<Backend> backend, DeviceDescription device);
  ~DeviceWorker();  // Stop()s

  void Post(Priority priority, DeviceTask task);
  // Runs the task in progress to its end, hands every queued task nullptr, joins the thread.
  void Stop();

  int queue_depth() const;
  // Streams bound to this worker (WorkerPool::AttachStream).
  int streams() const { return streams_.load(std::memory_order_relaxed); }
  const DeviceDescription& device() const { return device_; }
  const std::string& device_name() const { return device_.name; }

 private:
  friend class WorkerPool;
  void Loop();

  std::unique_ptr<Backend> backend_;
  DeviceDescription device_;
  std::atomic<int> streams_{0};
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  struct QueuedTask {
    DeviceTask task;
    std::chrono::steady_clock::time_point queued;
  };
  std::deque<QueuedTask> queues_[2];
  static constexpr std::chrono::milliseconds kBackgroundMaxWait{250};
  bool stopping_ = false;
  bool running_task_ = false;
  std::thread thread_;
};

// The compute workers of the daemon (at least one).
class WorkerPool {
 public:
  // At least one worker. Work that no worker's role takes goes to the first worker.
  explicit WorkerPool(std::vector<std::unique_ptr<DeviceWorker>> workers);
  // For a one-off task of `work`: among the workers taking it (RoleTakes), the one with the
  // shortest queue (ties: fewer streams, then the first).
  DeviceWorker& Pick(Priority work);
  // For a stream whose tasks are `work` (tracking: interactive; mapping: background): among
  // the workers taking it, the one with the fewest bound streams (ties: shorter queue, then
  // the first), now bound to one more; every AttachStream is matched by one DetachStream.
  DeviceWorker& AttachStream(Priority work);
  void DetachStream(DeviceWorker& worker);
  void StopAll();
  int total_queue_depth() const;
  std::vector<std::string> device_names() const;
  size_t size() const { return workers_.size(); }
  const DeviceWorker& worker(size_t i) const { return *workers_[i]; }
  DeviceWorker& worker(size_t i) { return *workers_[i]; }

 private:
  DeviceWorker& Least(Priority work, bool by_streams_first);

  std::vector<std::unique_ptr<DeviceWorker>> workers_;
  std::mutex attach_mutex_;
};

}  // namespace plx::server

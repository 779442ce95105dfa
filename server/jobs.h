// Background jobs (mapping) and their status, for WatchJob and progress reporting.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"

namespace plx::server {

enum class JobState { kQueued, kRunning, kDone, kFailed, kCancelled };

struct JobInfo {
  std::string id;
  std::string kind;  // "integrate"
  std::string map;
  JobState state = JobState::kQueued;
  double progress = 0.0;
  std::string message;
  bool terminal() const {
    return state == JobState::kDone || state == JobState::kFailed || state == JobState::kCancelled;
  }
};

class JobRegistry {
 public:
  using Listener = std::function<void(const JobInfo&)>;

  std::string Create(const std::string& kind, const std::string& map);
  void Update(const std::string& id, JobState state, double progress, const std::string& message);
  absl::StatusOr<JobInfo> Get(const std::string& id) const;
  // Calls `listener` now with the current status and after every change until Unwatch; returns
  // a handle for Unwatch. NotFound for an unknown job.
  absl::StatusOr<int64_t> Watch(const std::string& id, Listener listener);
  // After Unwatch returns the listener is not running and never runs again, so its owner may
  // be destroyed. A listener may unwatch itself (then only later calls are prevented).
  void Unwatch(int64_t handle);
  int running() const;

 private:
  struct Watcher {
    std::string job;
    Listener listener;
    int calls_in_flight = 0;  // guarded by mutex_
  };
  void Call(const std::shared_ptr<Watcher>& watcher, const JobInfo& info);

  mutable std::mutex mutex_;
  std::condition_variable calls_finished_;
  int64_t next_id_ = 1;
  int64_t next_handle_ = 1;
  std::map<std::string, JobInfo> jobs_;
  std::map<int64_t, std::shared_ptr<Watcher>> watchers_;
};

}  // namespace plx::server

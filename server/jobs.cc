#include "server/jobs.h"

#include <vector>

#include "absl/strings/str_cat.h"

namespace plx::server {

std::string JobRegistry::Create(const std::string& kind, const std::string& map) {
  std::lock_guard<std::mutex> lock(mutex_);
  JobInfo info;
  info.id = absl::StrCat(kind, "-", next_id_++);
  info.kind = kind;
  info.map = map;
  jobs_[info.id] = info;
  return info.id;
}

void JobRegistry::Update(const std::string& id, JobState state, double progress,
                         const std::string& message) {
  std::vector<Listener> to_call;
  JobInfo snapshot;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = jobs_.find(id);
    if (it == jobs_.end() || it->second.terminal()) return;
    it->second.state = state;
    it->second.progress = progress;
    it->second.message = message;
    snapshot = it->second;
    for (const auto& [handle, entry] : listeners_) {
      if (entry.first == id) to_call.push_back(entry.second);
    }
  }
  // Outside the lock: a listener may Unwatch.
  for (const Listener& listener : to_call) listener(snapshot);
}

absl::StatusOr<JobInfo> JobRegistry::Get(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = jobs_.find(id);
  if (it == jobs_.end()) return absl::NotFoundError(absl::StrCat("no job \"", id, "\""));
  return it->second;
}

absl::StatusOr<int64_t> JobRegistry::Watch(const std::string& id, Listener listener) {
  JobInfo now;
  int64_t handle = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = jobs_.find(id);
    if (it == jobs_.end()) return absl::NotFoundError(absl::StrCat("no job \"", id, "\""));
    now = it->second;
    handle = next_handle_++;
    listeners_[handle] = {id, listener};
  }
  listener(now);
  return handle;
}

void JobRegistry::Unwatch(int64_t handle) {
  std::lock_guard<std::mutex> lock(mutex_);
  listeners_.erase(handle);
}

int JobRegistry::running() const {
  std::lock_guard<std::mutex> lock(mutex_);
  int n = 0;
  for (const auto& [id, job] : jobs_) n += job.state == JobState::kRunning;
  return n;
}

}  // namespace plx::server

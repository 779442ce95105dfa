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

namespace {
// The watcher whose listener this thread is running, so that a listener unwatching itself does
// not wait for its own call to end.
thread_local const void* running_watcher = nullptr;
}  // namespace

// Listeners run outside the lock (they write to streams and may call back into the registry);
// the in-flight count lets Unwatch wait for a call that already left the lock.
void JobRegistry::Call(const std::shared_ptr<Watcher>& watcher, const JobInfo& info) {
  const void* outer = running_watcher;
  running_watcher = watcher.get();
  watcher->listener(info);
  running_watcher = outer;
  std::lock_guard<std::mutex> lock(mutex_);
  if (--watcher->calls_in_flight == 0) calls_finished_.notify_all();
}

void JobRegistry::Update(const std::string& id, JobState state, double progress,
                         const std::string& message) {
  std::vector<std::shared_ptr<Watcher>> to_call;
  JobInfo snapshot;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = jobs_.find(id);
    if (it == jobs_.end() || it->second.terminal()) return;
    it->second.state = state;
    it->second.progress = progress;
    it->second.message = message;
    snapshot = it->second;
    for (const auto& [handle, watcher] : watchers_) {
      if (watcher->job != id) continue;
      ++watcher->calls_in_flight;
      to_call.push_back(watcher);
    }
  }
  for (const std::shared_ptr<Watcher>& watcher : to_call) Call(watcher, snapshot);
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
  auto watcher = std::make_shared<Watcher>();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = jobs_.find(id);
    if (it == jobs_.end()) return absl::NotFoundError(absl::StrCat("no job \"", id, "\""));
    now = it->second;
    handle = next_handle_++;
    watcher->job = id;
    watcher->listener = std::move(listener);
    watcher->calls_in_flight = 1;
    watchers_[handle] = watcher;
  }
  Call(watcher, now);
  return handle;
}

void JobRegistry::Unwatch(int64_t handle) {
  std::unique_lock<std::mutex> lock(mutex_);
  auto it = watchers_.find(handle);
  if (it == watchers_.end()) return;
  std::shared_ptr<Watcher> watcher = it->second;
  watchers_.erase(it);
  const int own_call = running_watcher == watcher.get() ? 1 : 0;
  calls_finished_.wait(lock, [&] { return watcher->calls_in_flight <= own_call; });
}

int JobRegistry::running() const {
  std::lock_guard<std::mutex> lock(mutex_);
  int n = 0;
  for (const auto& [id, job] : jobs_) n += job.state == JobState::kRunning;
  return n;
}

}  // namespace plx::server

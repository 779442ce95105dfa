#include "server/stop_watchdog.h"

#include <unistd.h>

#include <chrono>
#include <memory>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "server/log.h"

namespace plx::server {
namespace {
// How long the watchdog waits for the names of the unsaved maps before it exits without them.
constexpr std::chrono::seconds kAskTimeout{2};
}  // namespace

StopWatchdog::StopWatchdog(absl::Duration limit, UnsavedMaps unsaved,
                           std::function<void()> expire)
    : unsaved_(std::move(unsaved)), expire_(std::move(expire)) {
  if (!expire_) expire_ = [] { ::_exit(kExitStopTimeout); };
  thread_ = std::thread([this, limit] { Run(limit); });
}

StopWatchdog::~StopWatchdog() {
  Disarm();
  thread_.join();
}

void StopWatchdog::Disarm() {
  std::lock_guard<std::mutex> lock(mutex_);
  disarmed_ = true;
  wake_.notify_all();
}

void StopWatchdog::Run(absl::Duration limit) {
  {
    std::unique_lock<std::mutex> lock(mutex_);
    const auto deadline = std::chrono::steady_clock::now() + absl::ToChronoNanoseconds(limit);
    if (wake_.wait_until(lock, deadline, [this] { return disarmed_; })) return;
  }
  // The names come from the map store, whose lock a stuck thread might hold: asked on a thread
  // of their own, waited for at most kAskTimeout, so the watchdog itself can never hang.
  struct Answer {
    std::mutex mutex;
    std::condition_variable ready;
    bool done = false;
    std::vector<std::string> names;
  };
  auto answer = std::make_shared<Answer>();
  std::thread([answer, unsaved = unsaved_] {
    std::vector<std::string> names = unsaved ? unsaved() : std::vector<std::string>();
    std::lock_guard<std::mutex> lock(answer->mutex);
    answer->names = std::move(names);
    answer->done = true;
    answer->ready.notify_all();
  }).detach();
  bool known = false;
  std::vector<std::string> unsaved;
  {
    std::unique_lock<std::mutex> lock(answer->mutex);
    known = answer->ready.wait_for(lock, kAskTimeout, [&] { return answer->done; });
    if (known) unsaved = answer->names;
  }
  LogEvent("error", "stop_timeout",
           {{"limit_s", absl::StrCat(absl::ToDoubleSeconds(limit))},
            {"unsaved_maps", known ? absl::StrJoin(unsaved, ",") : "unknown (map store busy)"},
            {"exit", std::to_string(kExitStopTimeout)}});
  for (const std::string& name : unsaved) {
    LogEvent("error", "map_not_saved", {{"map", name}, {"reason", "stop deadline passed"}});
  }
  expire_();
}

}  // namespace plx::server

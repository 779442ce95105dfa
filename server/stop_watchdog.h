// Bounds how long plenoxd takes to stop. Armed when SIGTERM arrives (main.cc), it gives the
// drain (--drain-seconds) and the saves of dirty maps (--stop-grace-seconds) their time; if
// that passes and the daemon has not stopped, whatever it is stuck on (a task that never
// returns, a hung file system, a stream that never finishes), it logs one line per map that was
// not saved and ends the process with kExitStopTimeout. An orchestrator then sees a failed stop
// and which maps were lost, instead of a process that ignores SIGTERM until SIGKILL.
#pragma once

#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/time/time.h"

namespace plx::server {

// plenoxd's exit status when the stop deadline passed (1: a save failed; 2: usage).
inline constexpr int kExitStopTimeout = 3;

class StopWatchdog {
 public:
  // Names of the maps not saved yet (MapStore::DirtyNames), asked when the deadline passes.
  using UnsavedMaps = std::function<std::vector<std::string>()>;

  // Starts counting now. When `limit` passes before Disarm(): logs "stop_timeout" and a
  // "map_not_saved" line per name of `unsaved()`, then calls `expire`; by default
  // _exit(kExitStopTimeout), which runs no destructor and waits for no thread.
  StopWatchdog(absl::Duration limit, UnsavedMaps unsaved, std::function<void()> expire = nullptr);
  ~StopWatchdog();  // Disarm()s and joins

  void Disarm();

 private:
  void Run(absl::Duration limit);

  UnsavedMaps unsaved_;
  std::function<void()> expire_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool disarmed_ = false;
  std::thread thread_;
};

}  // namespace plx::server

#include "server/snapshot_scheduler.h"

#include <algorithm>
#include <chrono>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "server/log.h"

namespace plx::server {
namespace {

// One snapshot, on the snapshot worker. Uses only the store and the metrics (both outlive the
// worker), not the scheduler.
void RunSnapshot(MapStore* maps, Metrics* metrics, const std::string& name,
                 absl::Duration retry_after, bool cancelled) {
  if (cancelled) {  // the daemon stops: the drain's own save takes over
    maps->ReleaseSnapshot(name);
    return;
  }
  const absl::StatusOr<SaveOutcome> saved = maps->Snapshot(name, retry_after);
  if (!saved.ok()) {
    metrics->snapshot_failures.fetch_add(1, std::memory_order_relaxed);
    LogEvent("warning", "snapshot_failed",
             {{"map", name},
              {"reason", std::string(saved.status().message())},
              {"retry_s", absl::StrFormat("%.1f", absl::ToDoubleSeconds(retry_after))}});
    return;
  }
  if (saved->skipped) return;
  metrics->snapshots.fetch_add(1, std::memory_order_relaxed);
  metrics->snapshot_bytes.fetch_add(saved->bytes, std::memory_order_relaxed);
  metrics->ObserveSnapshot(absl::ToDoubleSeconds(saved->took));
  LogEvent("info", "snapshot_saved",
           {{"map", name},
            {"version", absl::StrCat(saved->version)},
            {"keyframes", absl::StrCat(saved->keyframes)},
            {"bytes", absl::StrCat(saved->bytes)},
            {"seconds", absl::StrFormat("%.3f", absl::ToDoubleSeconds(saved->took))}});
}

}  // namespace

SnapshotScheduler::SnapshotScheduler(MapStore* maps, DeviceWorker* worker, Metrics* metrics,
                                     absl::Duration interval)
    : maps_(maps), worker_(worker), metrics_(metrics), interval_(interval),
      thread_([this] { Loop(); }) {}

SnapshotScheduler::~SnapshotScheduler() { Stop(); }

void SnapshotScheduler::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    wake_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
}

void SnapshotScheduler::Loop() {
  const absl::Duration max_sleep = std::min(kMaxSleep, interval_);
  for (;;) {
    const absl::Time now = absl::Now();
    for (const std::string& name : maps_->ClaimDueSnapshots(interval_, now)) {
      worker_->Post(Priority::kBackground,
                    [maps = maps_, metrics = metrics_, name, retry = interval_](
                        Backend*, bool cancelled) {
                      RunSnapshot(maps, metrics, name, retry, cancelled);
                    });
    }
    // Until the next map is due, at most max_sleep (a map that turns dirty meanwhile is due an
    // interval later, so it is never found more than max_sleep late).
    const absl::Time wake_at = std::min(maps_->NextSnapshotDue(interval_), now + max_sleep);
    const auto wait = std::chrono::microseconds(
        std::max<int64_t>(1000, absl::ToInt64Microseconds(wake_at - absl::Now())));
    std::unique_lock<std::mutex> lock(mutex_);
    if (wake_.wait_for(lock, wait, [this] { return stopping_; })) return;
  }
}

}  // namespace plx::server

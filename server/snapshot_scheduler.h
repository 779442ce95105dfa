// Background saves of maps with unsaved changes (plenoxd --snapshot-seconds, docs/LIMITS.md):
// a timer thread asks the map store which maps are due by core's rule (MapSaveState,
// core/formats/snapshot_policy.h) and posts one save per due map to the snapshot worker.
//
//   - Copy-on-write: a snapshot writes the version published when it starts, a
//     shared_ptr<const PlenoxelMap> no one writes (MapStore::Snapshot), so tracking, mapping
//     and readers never wait for it; the mapping job clones the bricks it changes meanwhile.
//   - Atomic as every save: a temporary next to the file, fsync, rename (core/io/atomic_write.h).
//     A crash mid-snapshot leaves the previous file and a temporary the next start removes.
//   - Bounded: the snapshot worker (a DeviceWorker without a backend) saves one map at a time;
//     a map is claimed when it is posted and not claimed again until its save ran, so a map is
//     never queued twice; a map whose save (a SaveMap call, a load) is running waits its turn.
//     The worker's thread runs at --mapping-nice, so on a busy CPU a snapshot takes the cycles
//     tracking leaves (docs/BENCHMARKS.md: a Track client's p99 with and without snapshots).
//   - Errors are logged (event=snapshot_failed) and counted (plenoxd_snapshot_failures_total),
//     never fatal; the map stays dirty and is tried again one interval later.
#pragma once

#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>

#include "absl/time/time.h"
#include "server/device_worker.h"
#include "server/map_store.h"
#include "server/metrics.h"

namespace plx::server {

class SnapshotScheduler {
 public:
  // `maps`, `worker` and `metrics` must outlive the scheduler; the worker's tasks use only
  // `maps` and `metrics`. `interval` > 0.
  SnapshotScheduler(MapStore* maps, DeviceWorker* worker, Metrics* metrics,
                    absl::Duration interval);
  ~SnapshotScheduler();  // Stop()s

  // No more snapshots are posted (the daemon drains; its worker still runs what was posted).
  void Stop();

  // The longest the timer sleeps: a map that turns dirty is due `interval` later, so polling at
  // this rate makes a snapshot at most this late.
  static constexpr absl::Duration kMaxSleep = absl::Seconds(1);

 private:
  void Loop();

  MapStore* const maps_;
  DeviceWorker* const worker_;
  Metrics* const metrics_;
  const absl::Duration interval_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace plx::server

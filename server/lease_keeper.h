// Keeps the daemon's leases on maps in shared storage (plenoxd --shared-dir): a timer thread
// that renews every lease the map store holds each LeaseTerms::renew_every
// (MapStore::RenewLeases; the rule is core's, core/storage/lease_policy.h). A renewal that
// finds the lease taken over drops the map (logged as event=lease_lost, naming the new
// generation); one that fails for another reason (the volume unreachable) is logged as
// event=lease_renew_failed and tried again next time. A lease not renewed in time stops the
// map's saves (the fence refuses them) until a renewal gets through. After each round of
// renewals it hands over the maps other daemons asked for and this one no longer uses
// (MapStore::HandOffWanted; logged as event=handoff_given, or event=handoff_failed when the
// save failed and the map stays).
#pragma once

#include <condition_variable>
#include <mutex>
#include <thread>

#include "absl/time/time.h"
#include "server/map_store.h"

namespace plx::server {

class LeaseKeeper {
 public:
  // `maps` must outlive the keeper; `every` > 0.
  LeaseKeeper(MapStore* maps, absl::Duration every);
  ~LeaseKeeper();  // Stop()s

  // No more renewals (the drain, once its saves are done, before the leases are given back).
  void Stop();

 private:
  void Loop();

  MapStore* const maps_;
  const absl::Duration every_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace plx::server

#include "server/lease_keeper.h"

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "server/log.h"

namespace plx::server {

LeaseKeeper::LeaseKeeper(MapStore* maps, absl::Duration every)
    : maps_(maps), every_(every), thread_([this] { Loop(); }) {}

LeaseKeeper::~LeaseKeeper() { Stop(); }

void LeaseKeeper::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    wake_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
}

void LeaseKeeper::Loop() {
  const auto wait =
      std::chrono::microseconds(std::max<int64_t>(1000, absl::ToInt64Microseconds(every_)));
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (wake_.wait_for(lock, wait, [this] { return stopping_; })) return;
    }
    for (const MapLeaseEvent& event : maps_->RenewLeases()) {
      LogEvent(event.lost ? "warning" : "error", event.lost ? "lease_lost" : "lease_renew_failed",
               {{"map", event.name}, {"reason", std::string(event.status.message())}});
    }
    for (const MapHandoffEvent& event : maps_->HandOffWanted()) {
      std::vector<LogField> fields = {{"map", event.name},
                                      {"to", event.to},
                                      {"version", std::to_string(event.version)},
                                      {"saved", event.saved ? "true" : "false"}};
      if (!event.status.ok()) fields.emplace_back("reason", std::string(event.status.message()));
      LogEvent(event.status.ok() ? "info" : "warning",
               event.status.ok() ? "handoff_given" : "handoff_failed", fields);
    }
  }
}

}  // namespace plx::server

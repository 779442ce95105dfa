#include "server/lease_keeper.h"

#include <algorithm>
#include <chrono>
#include <string>

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
  }
}

}  // namespace plx::server

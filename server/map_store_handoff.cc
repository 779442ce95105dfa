// The holder's side of a handoff (server/map_store.h, "Handoff"; the rule is core's,
// core/storage/lease_policy.h): a map another daemon asked for, idle here, is saved under the
// fence, dropped, and its lease released, reserved for the requester. Kept apart from the
// rest of the store: it is the one place where a store gives a healthy map away.
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/storage/lease_policy.h"
#include "server/map_store.h"

namespace plx::server {

std::vector<MapHandoffEvent> MapStore::HandOffWanted() {
  std::vector<MapHandoffEvent> events;
  if (!options_.shared) return events;
  std::vector<std::string> due;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const absl::Time now = options_.clock();
    for (const auto& [name, e] : maps_) {
      if (HandOffDue(e, now)) due.push_back(name);
    }
  }
  for (const std::string& name : due) {
    std::optional<MapHandoffEvent> event = HandOff(name);
    if (event.has_value()) events.push_back(*std::move(event));
  }
  return events;
}

bool MapStore::HandOffDue(const Entry& e, absl::Time now) const {
  return e.lost.ok() && e.lease_token != 0 && !e.wanted_by.empty() && e.moving_to.empty() &&
         ShouldHandOff(e.mapping, e.last_call, now, options_.lease);
}

std::optional<MapHandoffEvent> MapStore::HandOff(const std::string& name) {
  // No save, load or delete of the map meanwhile; snapshots claimed before find it gone.
  const FileTurn turn(this, name);
  MapHandoffEvent event;
  event.name = name;
  std::shared_ptr<const PlenoxelMap> map;
  MapFileState state;
  uint64_t token = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = maps_.find(name);
    if (it == maps_.end()) return std::nullopt;
    Entry& e = it->second;
    // Decided again under the turn: a call or a mapping job may have come meanwhile.
    if (!HandOffDue(e, options_.clock())) return std::nullopt;
    // From here on calls naming the map get UNAVAILABLE (Find), and no mapping job can start,
    // so the version saved below is the last one.
    e.moving_to = e.wanted_by;
    event.to = e.wanted_by;
    event.version = e.version;
    event.saved = e.save.dirty();
    token = e.lease_token;
    map = e.map;
    state.map_version = e.version;
    state.keyframes = *e.keyframes;
  }
  // A map made here and never saved has no file for the requester to load yet.
  if (!event.saved && absl::IsNotFound(options_.shared->Stat(name).status())) event.saved = true;
  if (event.saved) {
    const absl::Status saved = SaveShared(name, token, *map, state);
    if (!saved.ok()) {
      std::lock_guard<std::mutex> lock(mutex_);
      auto it = maps_.find(name);
      if (it != maps_.end()) it->second.moving_to.clear();
      if (IsLeaseLost(saved)) {
        ++fenced_saves_refused_;
        DropLost(name, saved);
      }
      // Kept (or lost): the requester waits for the next try, or for the lease to expire.
      event.status = absl::Status(saved.code(), absl::StrCat("map \"", name,
                                                             "\" was not handed over: ",
                                                             saved.message()));
      return event;
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    maps_.erase(name);
    ++handoffs_given_;
  }
  // Released with the request kept: reserved for the requester. A release that fails leaves
  // the map to move when the lease expires (nothing is written here any more).
  event.status = ReleaseLease(*options_.shared, name, options_.holder, token);
  return event;
}

int64_t MapStore::handoffs_given() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return handoffs_given_;
}

int64_t MapStore::handoffs_taken() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return handoffs_taken_;
}

}  // namespace plx::server

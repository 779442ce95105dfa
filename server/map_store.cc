#include "server/map_store.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "core/common/status_macros.h"
#include "core/cpu/cpu_backend.h"
#include "core/formats/map_file.h"
#include "core/kernels/backend.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/mapping/mapper.h"
#include "core/storage/lease_policy.h"
#include "proto/map_codec.h"

namespace plx::server {
namespace {

// The lease holder as the client knows it.
const char* HolderText(MappingJobKind kind) {
  return kind == MappingJobKind::kSlam ? "its SLAM job (Slam streams)" : "an Integrate stream";
}

}  // namespace

MapStore::MapStore(MapStoreOptions options) : options_(std::move(options)) {}

std::string MapStore::PathOf(const std::string& name) const {
  return (std::filesystem::path(options_.data_dir) / (name + ".plx")).string();
}

absl::Status MapStore::Missing(const std::string& name) const {
  auto lost = lost_.find(name);
  if (lost != lost_.end()) return lost->second.why;
  return absl::NotFoundError(absl::StrCat("no map named \"", name, "\""));
}

absl::Status MapStore::FullError() const {
  return absl::ResourceExhaustedError(
      absl::StrCat("the daemon holds its maximum of ", options_.max_maps, " maps"));
}

namespace {

// Calls naming a map while it is being handed over: retryable, and they say where it goes.
absl::Status MovingError(const std::string& name, const std::string& to) {
  return absl::UnavailableError(absl::StrCat("map \"", name, "\" is being handed over to daemon ",
                                             to, " (saved, then released); retry"));
}

}  // namespace

absl::StatusOr<MapStore::Entry*> MapStore::Find(const std::string& name) {
  auto it = maps_.find(name);
  if (it == maps_.end()) return Missing(name);
  if (!it->second.lost.ok()) return it->second.lost;
  if (!it->second.moving_to.empty()) return MovingError(name, it->second.moving_to);
  return &it->second;
}

absl::StatusOr<const MapStore::Entry*> MapStore::Find(const std::string& name) const {
  auto it = maps_.find(name);
  if (it == maps_.end()) return Missing(name);
  if (!it->second.lost.ok()) return it->second.lost;
  if (!it->second.moving_to.empty()) return MovingError(name, it->second.moving_to);
  return &it->second;
}

MapStatus MapStore::StatusOf(const std::string& name, const Entry& e) const {
  MapStatus s = MapStatusOf(name, *e.map);
  s.version = e.version;
  s.keyframes = e.keyframe_count;
  s.dirty = e.save.dirty();
  s.mapping = e.mapping;
  return s;
}

std::vector<std::string> MapStore::LoadAllFromDataDir() {
  std::vector<std::string> problems;
  if (options_.data_dir.empty()) return problems;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(options_.data_dir, ec)) {
    if (entry.path().extension() != ".plx") continue;
    // Only regular files (or links to them): reading a FIFO would block the start for ever.
    std::error_code type_ec;
    if (!entry.is_regular_file(type_ec)) {
      problems.push_back(absl::StrCat(entry.path().string(), ": not a regular file, skipped"));
      continue;
    }
    const std::string name = entry.path().stem().string();
    if (!CheckMapName(name, "file").ok()) {
      problems.push_back(absl::StrCat(entry.path().string(), ": not a valid map name, skipped"));
      continue;
    }
    absl::StatusOr<MapStatus> loaded = Load(name);
    if (!loaded.ok()) problems.push_back(std::string(loaded.status().message()));
  }
  if (ec) problems.push_back(absl::StrCat(options_.data_dir, ": ", ec.message()));
  return problems;
}

absl::StatusOr<MapStatus> MapStore::Create(const std::string& name, float voxel_size) {
  PLX_RETURN_IF_ERROR(CheckMapName(name, "name"));
  if (!VoxelSizeInRange(voxel_size)) {
    return absl::InvalidArgumentError(absl::StrCat("voxel_size: must be in [", kMinVoxelSize, ", ",
                                                   kMaxVoxelSize, "] metres, got ", voxel_size));
  }
  const auto refused = [&]() -> absl::Status {
    if (maps_.count(name)) {
      return absl::AlreadyExistsError(absl::StrCat("a map named \"", name, "\" exists"));
    }
    if (static_cast<int>(maps_.size()) >= options_.max_maps) return FullError();
    return absl::OkStatus();
  };
  // Shared storage: one Create or load of the name at a time, so two calls never both take
  // its lease (the second would take it anew and fence the first off).
  std::optional<FileTurn> turn;
  if (options_.shared) turn.emplace(this, name);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    PLX_RETURN_IF_ERROR(refused());
  }
  // Shared storage: a stored map is loaded, never made anew over its file; a new one is held
  // under its lease from the start, so two daemons cannot both make it.
  uint64_t token = 0;
  if (options_.shared) {
    absl::StatusOr<StoredMapInfo> stored = options_.shared->Stat(name);
    if (stored.ok()) {
      return absl::AlreadyExistsError(
          absl::StrCat("a map named \"", name, "\" is in shared storage (",
                       options_.shared->Describe(), "); name it in any call to load it"));
    }
    if (!absl::IsNotFound(stored.status())) return stored.status();
    PLX_ASSIGN_OR_RETURN(const LeaseRecord lease,
                         AcquireLease(*options_.shared, name, options_.holder, 0,
                                      options_.clock, options_.lease));
    token = lease.token;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  if (absl::Status s = refused(); !s.ok()) {
    // Another call made it meanwhile (under its own token: ours is given back).
    lock.unlock();
    if (token != 0) {
      ReleaseLease(*options_.shared, name, options_.holder, token).IgnoreError();
    }
    return s;
  }
  Entry e;
  e.lease_token = token;
  e.last_call = options_.clock();
  lost_.erase(name);
  auto empty = std::make_shared<PlenoxelMap>(voxel_size);
  empty->grid.set_occupancy_fresh();  // empty: nothing to refresh
  e.map = std::move(empty);
  e.save.MarkClean(e.version);  // nothing worth saving yet
  auto [it, inserted] = maps_.emplace(name, std::move(e));
  return StatusOf(name, it->second);
}

absl::StatusOr<MapStatus> MapStore::Info(const std::string& name) {
  PLX_RETURN_IF_ERROR(HoldShared(name));
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(const Entry* e, Find(name));
  return StatusOf(name, *e);
}

std::vector<MapStatus> MapStore::List() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<MapStatus> out;
  for (const auto& [name, e] : maps_) {
    if (e.lost.ok()) out.push_back(StatusOf(name, e));
  }
  return out;
}

absl::StatusOr<MapVersion> MapStore::Latest(const std::string& name) {
  PLX_RETURN_IF_ERROR(HoldShared(name));
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(const Entry* e, Find(name));
  return MapVersion{e->map, e->version, e->keyframes};
}

MapStore::FileTurn::FileTurn(MapStore* store, std::string name)
    : store_(store), name_(std::move(name)) {
  std::unique_lock<std::mutex> lock(store_->mutex_);
  store_->file_free_.wait(lock, [&] { return store_->file_busy_.count(name_) == 0; });
  store_->file_busy_.insert(name_);
}

MapStore::FileTurn::~FileTurn() {
  std::lock_guard<std::mutex> lock(store_->mutex_);
  store_->file_busy_.erase(name_);
  store_->file_free_.notify_all();
}

absl::Status MapStore::Delete(const std::string& name) {
  PLX_RETURN_IF_ERROR(Info(name).status());
  // A save running now would rename its file into place after the unlink below.
  const FileTurn turn(this, name);
  std::unique_lock<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(Entry * e, Find(name));
  if (e->mapping) {
    return absl::FailedPreconditionError(absl::StrCat(
        "map \"", name, "\" is being mapped by ", HolderText(e->mapping_kind), "; ",
        e->mapping_kind == MappingJobKind::kSlam
            ? "end its Slam streams first (the job ends after the last one)"
            : "cancel that stream (or let it finish) first"));
  }
  // The file first: a map whose file stays would come back at the next start (or, shared,
  // at the next call naming it). Shared: only while the lease is still this store's (the
  // storage's lock is held for milliseconds; mutex_ stays held so no mapping job starts).
  const uint64_t token = e->lease_token;
  if (options_.shared) {
    absl::Status removed = options_.shared->RemoveFenced(name, [&](const LeaseRecord& current) {
      return CheckFence(name, current, options_.holder, token, options_.clock(), options_.lease);
    });
    if (IsLeaseLost(removed)) DropLost(name, removed);
    if (!removed.ok()) {
      return absl::Status(removed.code(), absl::StrCat("map \"", name, "\" was not deleted: ",
                                                       removed.message()));
    }
    maps_.erase(name);
    lock.unlock();
    ReleaseLease(*options_.shared, name, options_.holder, token).IgnoreError();
    return absl::OkStatus();
  }
  if (!e->file.empty() && ::unlink(e->file.c_str()) != 0) {
    const int err = errno;
    if (err != ENOENT) {
      return FileWriteError(err, absl::StrCat("map \"", name, "\" was not deleted: removing ",
                                              e->file));
    }
  }
  maps_.erase(name);
  return absl::OkStatus();
}

absl::StatusOr<SaveOutcome> MapStore::SaveNewest(const std::string& name, bool snapshot,
                                                  absl::Duration retry_after) {
  if (options_.data_dir.empty() && !options_.shared) {
    return absl::FailedPreconditionError("the daemon has no --data-dir to save maps to");
  }
  SaveOutcome out;
  // A snapshot of a map deleted since it was claimed has nothing to do.
  const auto gone = [&](const absl::Status& not_found) -> absl::StatusOr<SaveOutcome> {
    if (!snapshot) return not_found;
    out.skipped = true;
    return out;
  };
  {
    std::lock_guard<std::mutex> lock(mutex_);
    absl::StatusOr<Entry*> e = Find(name);
    if (!e.ok()) return gone(e.status());
    if (snapshot) (*e)->snapshot_claimed = false;
  }
  const FileTurn turn(this, name);
  std::shared_ptr<const PlenoxelMap> map;
  MapFileState state;
  uint64_t token = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    absl::StatusOr<Entry*> e = Find(name);  // it may have gone while we waited
    if (!e.ok()) return gone(e.status());
    // A snapshot that a save (or another snapshot) made pointless writes nothing.
    if (snapshot && !(*e)->save.dirty()) {
      out.skipped = true;
      return out;
    }
    // The newest version, taken now (not when the save was asked for): a version nobody
    // writes, so the file is written while mapping and readers carry on.
    map = (*e)->map;
    token = (*e)->lease_token;
    state.map_version = (*e)->version;
    state.keyframes = *(*e)->keyframes;  // shared features: copies of pointers and poses
    (*e)->save.SaveStarted((*e)->version, absl::Now());
  }
  out.version = state.map_version;
  out.keyframes = static_cast<int>(state.keyframes.size());
  if (options_.test_only_save_delay > absl::ZeroDuration()) {
    absl::SleepFor(options_.test_only_save_delay);
  }
  const absl::Time start = absl::Now();
  const std::string path = options_.shared ? std::string() : PathOf(name);
  const absl::Status saved =
      options_.shared ? SaveShared(name, token, *map, state) : SaveMap(*map, state, path);
  out.took = absl::Now() - start;
  if (saved.ok()) {
    if (options_.shared) {
      absl::StatusOr<StoredMapInfo> stored = options_.shared->Stat(name);
      out.bytes = stored.ok() ? stored->bytes : 0;
    } else {
      std::error_code ec;
      out.bytes = static_cast<int64_t>(std::filesystem::file_size(path, ec));
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (IsLeaseLost(saved)) {
    // Nothing was published: the map is someone else's now, and this copy goes.
    ++fenced_saves_refused_;
    DropLost(name, saved);
    return saved;
  }
  absl::StatusOr<Entry*> e = Find(name);
  if (!e.ok()) {
    // Deleted while it was written: the file must not bring it back at the next start. (A
    // shared map cannot be: Delete waits for this save's turn, and a lost lease is above.)
    if (saved.ok() && !options_.shared) ::unlink(path.c_str());
    return gone(e.status());
  }
  (*e)->save.SaveFinished(saved.ok(), absl::Now(), retry_after);
  PLX_RETURN_IF_ERROR(saved);
  (*e)->file = path;
  out.status = StatusOf(name, **e);
  return out;
}

absl::Status MapStore::SaveShared(const std::string& name, uint64_t token,
                                  const PlenoxelMap& map, const MapFileState& state) {
  // Run by the storage on the lease record before the file is written and again, atomically,
  // when it is published.
  const auto may_write = [&](const LeaseRecord& current) {
    return CheckFence(name, current, options_.holder, token, options_.clock(), options_.lease);
  };
  return options_.shared->WriteFenced(
      name, may_write, [&](const std::string& path) { return SaveMap(map, state, path); });
}

absl::StatusOr<MapStatus> MapStore::Save(const std::string& name) {
  // Shared: a call naming a map loads it first, as every other one does.
  PLX_RETURN_IF_ERROR(HoldShared(name));
  PLX_ASSIGN_OR_RETURN(SaveOutcome outcome,
                       SaveNewest(name, /*snapshot=*/false, absl::ZeroDuration()));
  return outcome.status;
}

absl::StatusOr<SaveOutcome> MapStore::Snapshot(const std::string& name,
                                               absl::Duration retry_after) {
  return SaveNewest(name, /*snapshot=*/true, retry_after);
}

void MapStore::ReleaseSnapshot(const std::string& name) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = maps_.find(name);
  if (it != maps_.end()) it->second.snapshot_claimed = false;
}

std::vector<std::string> MapStore::ClaimDueSnapshots(absl::Duration interval, absl::Time now) {
  std::vector<std::string> due;
  if (options_.data_dir.empty() && !options_.shared) return due;
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [name, e] : maps_) {
    if (!e.lost.ok() || e.snapshot_claimed || file_busy_.count(name) != 0) continue;
    if (!e.save.SnapshotDue(interval, now)) continue;
    e.snapshot_claimed = true;
    due.push_back(name);
  }
  return due;
}

absl::Time MapStore::NextSnapshotDue(absl::Duration interval) const {
  std::lock_guard<std::mutex> lock(mutex_);
  absl::Time next = absl::InfiniteFuture();
  if (options_.data_dir.empty() && !options_.shared) return next;
  for (const auto& [name, e] : maps_) {
    if (e.lost.ok() && !e.snapshot_claimed) {
      next = std::min(next, e.save.NextSnapshotDue(interval));
    }
  }
  return next;
}

absl::Time MapStore::OldestUnsavedChange() const {
  std::lock_guard<std::mutex> lock(mutex_);
  absl::Time oldest = absl::InfiniteFuture();
  for (const auto& [name, e] : maps_) {
    if (e.lost.ok()) oldest = std::min(oldest, e.save.unsaved_since());
  }
  return oldest;
}

absl::StatusOr<MapStatus> MapStore::Load(const std::string& name) {
  PLX_RETURN_IF_ERROR(CheckMapName(name, "name"));
  if (options_.shared) return LoadShared(name, /*only_if_absent=*/false);
  if (options_.data_dir.empty()) {
    return absl::FailedPreconditionError("the daemon has no --data-dir to load maps from");
  }
  const std::string path = PathOf(name);
  if (!std::filesystem::exists(path)) {
    return absl::NotFoundError(absl::StrCat("no saved map \"", name, "\" (", path, ")"));
  }
  {
    // A full store refuses before reading the file (checked again below).
    std::lock_guard<std::mutex> lock(mutex_);
    if (!maps_.count(name) && static_cast<int>(maps_.size()) >= options_.max_maps) {
      return FullError();
    }
  }
  // A save of this map running now would replace the file under the read.
  const FileTurn turn(this, name);
  PLX_ASSIGN_OR_RETURN(LoadedFile file, ReadFile(path));
  std::lock_guard<std::mutex> lock(mutex_);
  return Install(name, std::move(file), path, /*lease_token=*/0);
}

absl::StatusOr<MapStore::LoadedFile> MapStore::ReadFile(const std::string& path) const {
  LoadMapOptions load;
  load.max_memory_bytes = options_.max_map_bytes;
  PLX_ASSIGN_OR_RETURN(LoadedMapFile loaded, LoadMapFile(path, load));
  // Published maps are shared by concurrent readers, so they must not need a lazy refresh.
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*MakeCpuBackend(), *loaded.map));
  LoadedFile file;
  file.map = std::move(loaded.map);
  file.keyframes = std::make_shared<const MapKeyframes>(std::move(loaded.state.keyframes));
  file.saved_version = loaded.state.map_version;
  return file;
}

absl::StatusOr<MapStatus> MapStore::Install(const std::string& name, LoadedFile file,
                                            const std::string& path, uint64_t lease_token) {
  auto it = maps_.find(name);
  if (it == maps_.end()) {
    if (static_cast<int>(maps_.size()) >= options_.max_maps) return FullError();
    it = maps_.emplace(name, Entry{}).first;
  } else if (!it->second.lost.ok()) {
    return it->second.lost;
  } else if (it->second.mapping) {
    return absl::FailedPreconditionError(
        absl::StrCat("map \"", name, "\" is being mapped; it cannot be replaced now"));
  }
  Entry& e = it->second;
  const bool fresh = e.map == nullptr;
  e.map = std::move(file.map);
  // The number it was saved at, so a restarted daemon goes on counting from it; a map replaced
  // in place still moves forward (readers compare numbers). Version-1 files have none.
  const uint64_t saved_version = file.saved_version;
  e.version = fresh ? (saved_version > 0 ? saved_version : 2)
                    : std::max(e.version + 1, saved_version);
  e.keyframe_count = static_cast<int>(file.keyframes->size());
  e.keyframes = std::move(file.keyframes);
  e.save.MarkClean(e.version);
  e.file = path;
  e.lease_token = lease_token;
  e.last_call = options_.clock();
  e.wanted_by.clear();
  lost_.erase(name);
  return StatusOf(name, e);
}

absl::Status MapStore::HoldShared(const std::string& name) {
  if (!options_.shared) return absl::OkStatus();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = maps_.find(name);
    if (it != maps_.end()) {
      // Every call naming a map passes here: a map its callers still use is not handed over.
      it->second.last_call = options_.clock();
      return absl::OkStatus();
    }
  }
  // Names no file can have are the lookup's to refuse (NotFound), as without shared storage.
  if (!CheckMapName(name, "name").ok()) return absl::OkStatus();
  absl::StatusOr<StoredMapInfo> stored = options_.shared->Stat(name);
  // Not stored, but maybe made (and not saved yet) by another daemon: its holder saves it
  // when it hands it over.
  if (absl::IsNotFound(stored.status())) return RequestUnsaved(name);
  if (!stored.ok()) return stored.status();
  absl::StatusOr<MapStatus> loaded = LoadShared(name, /*only_if_absent=*/true);
  if (loaded.ok() || IsLeaseLost(loaded.status())) return loaded.status();
  return absl::Status(loaded.status().code(),
                      absl::StrCat("map \"", name, "\" is in shared storage (",
                                   options_.shared->Describe(), ") but was not loaded: ",
                                   loaded.status().message()));
}

absl::StatusOr<MapStatus> MapStore::LoadShared(const std::string& name, bool only_if_absent) {
  {
    // A full store refuses before taking a lease or reading the file (checked again below).
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = maps_.find(name);
    if (it == maps_.end() && static_cast<int>(maps_.size()) >= options_.max_maps) {
      return FullError();
    }
  }
  // One load, save or delete of the map at a time: two calls naming a map not held load it
  // once, and a save of it cannot run under the read.
  const FileTurn turn(this, name);
  uint64_t held = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (maps_.count(name)) {
      PLX_ASSIGN_OR_RETURN(const Entry* e, Find(name));
      if (only_if_absent) return StatusOf(name, *e);  // another call loaded it meanwhile
      held = e->lease_token;
    }
  }
  // Only a stored map gets a lease (and lease files) for a load.
  if (held == 0) PLX_RETURN_IF_ERROR(options_.shared->Stat(name).status());
  bool recently_lost = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    recently_lost = RecentlyLost(name, options_.clock());
  }
  // A map another daemon holds is asked for (handoff), unless this store just lost it.
  bool handed_over = false;
  absl::StatusOr<LeaseRecord> lease =
      held == 0 && !recently_lost
          ? TakeOrRequestLease(*options_.shared, name, options_.holder, options_.clock,
                               options_.lease, &handed_over)
          : AcquireLease(*options_.shared, name, options_.holder, held, options_.clock,
                         options_.lease);
  if (!lease.ok()) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (IsLeaseLost(lease.status())) DropLost(name, lease.status());
    return lease.status();
  }
  // A lease taken for this load alone is given back when the load fails, so another daemon
  // need not wait for it to expire.
  const auto failed = [&](const absl::Status& why) {
    if (held == 0) {
      ReleaseLease(*options_.shared, name, options_.holder, lease->token).IgnoreError();
    }
    return why;
  };
  absl::StatusOr<std::string> path = options_.shared->LocalPath(name);
  if (!path.ok()) return failed(path.status());
  absl::StatusOr<LoadedFile> file = ReadFile(*path);
  if (!file.ok()) return failed(file.status());
  absl::StatusOr<MapStatus> installed;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    installed = Install(name, *std::move(file), *path, lease->token);
    if (installed.ok() && handed_over) ++handoffs_taken_;
  }
  if (!installed.ok()) return failed(installed.status());
  return installed;
}

absl::Status MapStore::RequestUnsaved(const std::string& name) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (RecentlyLost(name, options_.clock())) return absl::OkStatus();
  }
  absl::StatusOr<LeaseRecord> lease = options_.shared->ReadLease(name);
  if (!lease.ok()) return lease.status();
  // Free or ours: nobody else has it, so it does not exist (the lookup says so).
  if (LeaseFree(*lease, options_.clock()) || lease->holder == options_.holder) {
    return absl::OkStatus();
  }
  absl::StatusOr<LeaseRecord> asked = RecordHandoffRequest(*options_.shared, name,
                                                           options_.holder, options_.clock,
                                                           options_.lease);
  if (absl::IsFailedPrecondition(asked.status())) return absl::OkStatus();  // freed meanwhile
  if (!asked.ok()) return asked.status();
  return HandoffRequestedError(name, *asked, options_.lease);
}

bool MapStore::RecentlyLost(const std::string& name, absl::Time now) const {
  auto it = lost_.find(name);
  return it != lost_.end() && now - it->second.at < 2 * options_.lease.term;
}

void MapStore::DropLost(const std::string& name, const absl::Status& why) {
  auto it = maps_.find(name);
  if (it == maps_.end() || !it->second.lost.ok()) return;
  ++lease_losses_;
  lost_[name] = LostMap{why, options_.clock()};
  if (it->second.mapping) {
    it->second.lost = why;
  } else {
    maps_.erase(it);
  }
}

std::vector<MapLeaseEvent> MapStore::RenewLeases() {
  std::vector<MapLeaseEvent> events;
  if (!options_.shared) return events;
  std::vector<std::pair<std::string, uint64_t>> held;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [name, e] : maps_) {
      if (e.lost.ok() && e.lease_token != 0) held.emplace_back(name, e.lease_token);
    }
  }
  // Storage I/O without mutex_: a slow volume delays renewals, never the maps' readers.
  for (const auto& [name, token] : held) {
    absl::StatusOr<LeaseRecord> renewed = AcquireLease(*options_.shared, name, options_.holder,
                                                       token, options_.clock, options_.lease);
    if (renewed.ok()) {
      // A request the record carries, for HandOffWanted.
      std::lock_guard<std::mutex> lock(mutex_);
      auto it = maps_.find(name);
      if (it != maps_.end() && it->second.lease_token == token) {
        const bool wanted = HandoffPending(*renewed, options_.holder, options_.clock());
        it->second.wanted_by = wanted ? renewed->wanted_by : std::string();
      }
      continue;
    }
    const bool lost = IsLeaseLost(renewed.status());
    if (lost) {
      std::lock_guard<std::mutex> lock(mutex_);
      auto it = maps_.find(name);
      // Only the copy held under that token (a load may have replaced it meanwhile).
      if (it != maps_.end() && it->second.lease_token == token) DropLost(name, renewed.status());
    }
    events.push_back({name, renewed.status(), lost});
  }
  return events;
}

std::vector<MapLeaseEvent> MapStore::ReleaseLeases() {
  std::vector<MapLeaseEvent> events;
  if (!options_.shared) return events;
  std::vector<std::pair<std::string, uint64_t>> held;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [name, e] : maps_) {
      if (e.lost.ok() && e.lease_token != 0) held.emplace_back(name, e.lease_token);
      // No token, no write: a save after this is refused by the fence.
      e.lease_token = 0;
    }
  }
  for (const auto& [name, token] : held) {
    absl::Status released = ReleaseLease(*options_.shared, name, options_.holder, token);
    if (!released.ok()) events.push_back({name, released, false});
  }
  return events;
}

int MapStore::leases_held() const {
  std::lock_guard<std::mutex> lock(mutex_);
  int held = 0;
  for (const auto& [name, e] : maps_) held += e.lost.ok() && e.lease_token != 0;
  return held;
}

int64_t MapStore::lease_losses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lease_losses_;
}

int64_t MapStore::fenced_saves_refused() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return fenced_saves_refused_;
}

std::vector<UnsavedMap> MapStore::SaveDirty() {
  std::vector<UnsavedMap> unsaved;
  for (const MapStatus& s : List()) {
    if (!s.dirty) continue;
    absl::StatusOr<MapStatus> saved = Save(s.name);
    if (!saved.ok()) unsaved.push_back({s.name, saved.status()});
  }
  return unsaved;
}

std::vector<std::string> MapStore::DirtyNames() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::string> names;
  for (const auto& [name, e] : maps_) {
    if (e.lost.ok() && e.save.dirty()) names.push_back(name);
  }
  return names;
}

std::vector<StaleTempFile> MapStore::RemoveStaleTempFiles() {
  if (options_.data_dir.empty()) return {};
  return plx::RemoveStaleTempFiles(options_.data_dir, ".plx");
}

absl::Status MapStore::BeginMapping(const std::string& name, MappingJobKind kind) {
  PLX_RETURN_IF_ERROR(HoldShared(name));
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(Entry * e, Find(name));
  if (e->mapping) {
    return absl::FailedPreconditionError(absl::StrCat("map \"", name,
                                                      "\" already has a mapping job, ",
                                                      HolderText(e->mapping_kind),
                                                      " (one writer per map)"));
  }
  e->mapping = true;
  e->mapping_kind = kind;
  return absl::OkStatus();
}

void MapStore::EndMapping(const std::string& name) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = maps_.find(name);
  if (it == maps_.end()) return;
  it->second.mapping = false;
  if (!it->second.lost.ok()) maps_.erase(it);  // a lost map's tombstone: its job has ended
}

absl::StatusOr<uint64_t> MapStore::Publish(const std::string& name,
                                           std::shared_ptr<const PlenoxelMap> map,
                                           int keyframes_added,
                                           std::shared_ptr<const MapKeyframes> keyframes) {
  if (map->grid.occupancy_stale()) {
    return absl::InternalError("a map version was published with stale occupancy");
  }
  const int64_t bytes = map->grid.Memory().total_bytes();
  if (bytes > options_.max_map_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "map \"", name, "\" would need ", bytes / 1000000, " MB, over the limit of ",
        options_.max_map_bytes / 1000000, " MB per map"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(Entry * e, Find(name));
  e->map = std::move(map);
  e->version += 1;
  if (keyframes != nullptr) {
    e->keyframe_count = static_cast<int>(keyframes->size());
    e->keyframes = std::move(keyframes);
  } else {
    e->keyframe_count += keyframes_added;
  }
  e->save.Changed(e->version, absl::Now());
  return e->version;
}

int64_t MapStore::TotalBytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  int64_t total = 0;
  for (const auto& [name, e] : maps_) total += e.map->grid.Memory().total_bytes();
  return total;
}

int MapStore::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(maps_.size());
}

}  // namespace plx::server

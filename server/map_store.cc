#include "server/map_store.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "core/common/status_macros.h"
#include "core/cpu/cpu_backend.h"
#include "core/formats/map_file.h"
#include "core/kernels/backend.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/mapping/mapper.h"
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

absl::StatusOr<MapStore::Entry*> MapStore::Find(const std::string& name) {
  auto it = maps_.find(name);
  if (it == maps_.end()) return absl::NotFoundError(absl::StrCat("no map named \"", name, "\""));
  return &it->second;
}

absl::StatusOr<const MapStore::Entry*> MapStore::Find(const std::string& name) const {
  auto it = maps_.find(name);
  if (it == maps_.end()) return absl::NotFoundError(absl::StrCat("no map named \"", name, "\""));
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
  std::lock_guard<std::mutex> lock(mutex_);
  if (maps_.count(name)) {
    return absl::AlreadyExistsError(absl::StrCat("a map named \"", name, "\" exists"));
  }
  if (static_cast<int>(maps_.size()) >= options_.max_maps) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the daemon holds its maximum of ", options_.max_maps, " maps"));
  }
  Entry e;
  auto empty = std::make_shared<PlenoxelMap>(voxel_size);
  empty->grid.set_occupancy_fresh();  // empty: nothing to refresh
  e.map = std::move(empty);
  e.save.MarkClean(e.version);  // nothing worth saving yet
  auto [it, inserted] = maps_.emplace(name, std::move(e));
  return StatusOf(name, it->second);
}

absl::StatusOr<MapStatus> MapStore::Info(const std::string& name) const {
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(const Entry* e, Find(name));
  return StatusOf(name, *e);
}

std::vector<MapStatus> MapStore::List() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<MapStatus> out;
  for (const auto& [name, e] : maps_) out.push_back(StatusOf(name, e));
  return out;
}

absl::StatusOr<MapVersion> MapStore::Latest(const std::string& name) const {
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
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_ASSIGN_OR_RETURN(Entry * e, Find(name));
  if (e->mapping) {
    return absl::FailedPreconditionError(absl::StrCat(
        "map \"", name, "\" is being mapped by ", HolderText(e->mapping_kind), "; ",
        e->mapping_kind == MappingJobKind::kSlam
            ? "end its Slam streams first (the job ends after the last one)"
            : "cancel that stream (or let it finish) first"));
  }
  // The file first: a map whose file stays would come back at the next start.
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
  if (options_.data_dir.empty()) {
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
  const std::string path = PathOf(name);
  const absl::Status saved = SaveMap(*map, state, path);
  out.took = absl::Now() - start;
  if (saved.ok()) {
    std::error_code ec;
    out.bytes = static_cast<int64_t>(std::filesystem::file_size(path, ec));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  absl::StatusOr<Entry*> e = Find(name);
  if (!e.ok()) {
    // Deleted while it was written: the file must not bring it back at the next start.
    if (saved.ok()) ::unlink(path.c_str());
    return gone(e.status());
  }
  (*e)->save.SaveFinished(saved.ok(), absl::Now(), retry_after);
  PLX_RETURN_IF_ERROR(saved);
  (*e)->file = path;
  return out;
}

absl::StatusOr<MapStatus> MapStore::Save(const std::string& name) {
  PLX_RETURN_IF_ERROR(SaveNewest(name, /*snapshot=*/false, absl::ZeroDuration()).status());
  return Info(name);
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
  if (options_.data_dir.empty()) return due;
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [name, e] : maps_) {
    if (e.snapshot_claimed || file_busy_.count(name) != 0) continue;
    if (!e.save.SnapshotDue(interval, now)) continue;
    e.snapshot_claimed = true;
    due.push_back(name);
  }
  return due;
}

absl::Time MapStore::NextSnapshotDue(absl::Duration interval) const {
  std::lock_guard<std::mutex> lock(mutex_);
  absl::Time next = absl::InfiniteFuture();
  if (options_.data_dir.empty()) return next;
  for (const auto& [name, e] : maps_) {
    if (!e.snapshot_claimed) next = std::min(next, e.save.NextSnapshotDue(interval));
  }
  return next;
}

absl::Time MapStore::OldestUnsavedChange() const {
  std::lock_guard<std::mutex> lock(mutex_);
  absl::Time oldest = absl::InfiniteFuture();
  for (const auto& [name, e] : maps_) oldest = std::min(oldest, e.save.unsaved_since());
  return oldest;
}

absl::StatusOr<MapStatus> MapStore::Load(const std::string& name) {
  PLX_RETURN_IF_ERROR(CheckMapName(name, "name"));
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
      return absl::ResourceExhaustedError(
          absl::StrCat("the daemon holds its maximum of ", options_.max_maps, " maps"));
    }
  }
  // A save of this map running now would replace the file under the read.
  const FileTurn turn(this, name);
  LoadMapOptions load;
  load.max_memory_bytes = options_.max_map_bytes;
  PLX_ASSIGN_OR_RETURN(LoadedMapFile loaded, LoadMapFile(path, load));
  // Published maps are shared by concurrent readers, so they must not need a lazy refresh.
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*MakeCpuBackend(), *loaded.map));
  std::shared_ptr<const PlenoxelMap> map(std::move(loaded.map));
  auto keyframes = std::make_shared<const MapKeyframes>(std::move(loaded.state.keyframes));
  const uint64_t saved_version = loaded.state.map_version;
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = maps_.find(name);
  if (it == maps_.end()) {
    if (static_cast<int>(maps_.size()) >= options_.max_maps) {
      return absl::ResourceExhaustedError(
          absl::StrCat("the daemon holds its maximum of ", options_.max_maps, " maps"));
    }
    it = maps_.emplace(name, Entry{}).first;
  } else if (it->second.mapping) {
    return absl::FailedPreconditionError(
        absl::StrCat("map \"", name, "\" is being mapped; it cannot be replaced now"));
  }
  Entry& e = it->second;
  const bool fresh = e.map == nullptr;
  e.map = std::move(map);
  // The number it was saved at, so a restarted daemon goes on counting from it; a map replaced
  // in place still moves forward (readers compare numbers). Version-1 files have none.
  e.version = fresh ? (saved_version > 0 ? saved_version : 2)
                    : std::max(e.version + 1, saved_version);
  e.keyframe_count = static_cast<int>(keyframes->size());
  e.keyframes = std::move(keyframes);
  e.save.MarkClean(e.version);
  e.file = path;
  return StatusOf(name, e);
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
    if (e.save.dirty()) names.push_back(name);
  }
  return names;
}

std::vector<StaleTempFile> MapStore::RemoveStaleTempFiles() {
  if (options_.data_dir.empty()) return {};
  return plx::RemoveStaleTempFiles(options_.data_dir, ".plx");
}

absl::Status MapStore::BeginMapping(const std::string& name, MappingJobKind kind) {
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
  if (it != maps_.end()) it->second.mapping = false;
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

// The daemon's maps (DESIGN.md §10). Readers (tracking, render, export) take the latest
// published version, a shared_ptr to an immutable map, and keep it as long as they need; one
// mapping job per map works on its own copy and publishes new versions, so readers never wait
// for a mapping pass and never see a half-written map. Maps persist as <data_dir>/<name>.plx,
// each with its keyframes (core/formats/map_keyframe.h), which every published version carries
// beside its grid, and the version number it was saved at.
//
// Saving: a save writes a published version (copy-on-write: mapping and readers carry on while
// the file is written) and knows which version it wrote, so changes published meanwhile keep
// the map dirty. A map's file is touched by one operation at a time (save, snapshot, load,
// delete wait for each other), so two saves never share the atomic writer's temporary.
// Snapshots (server/snapshot_scheduler.h) are saves the store picks by core's rule
// (core/formats/snapshot_policy.h): ClaimDueSnapshots, then Snapshot or ReleaseSnapshot.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/formats/map_keyframe.h"
#include "core/formats/snapshot_policy.h"
#include "core/grid/map_status.h"
#include "core/grid/plenoxel_map.h"
#include "core/io/atomic_write.h"

namespace plx::server {

struct MapStoreOptions {
  std::string data_dir;               // empty: nothing is persisted
  int max_maps = 16;
  int64_t max_map_bytes = int64_t{4} << 30;
  // TEST ONLY (the stop watchdog's test, via $PLENOXD_TEST_ONLY_SAVE_DELAY_S in main.cc): every
  // save first sleeps this long, a save stuck on a hung file system. Zero in production.
  absl::Duration test_only_save_delay = absl::ZeroDuration();
};

// Maps are listed as core's MapStatus (core/grid/map_status.h).

// A dirty map that could not be saved, and why.
struct UnsavedMap {
  std::string name;
  absl::Status reason;
};

// What holds a map's mapping lease: errors about a busy map name it, so the client knows what to
// stop (an Integrate stream it opened, or the Slam streams feeding the map's SLAM job).
enum class MappingJobKind { kIntegrate, kSlam };

// A published map: immutable, shared by every reader, its occupancy exact; with the keyframes
// it was built from as its file keeps them (never null from the store; empty when unknown).
struct MapVersion {
  std::shared_ptr<const PlenoxelMap> map;
  uint64_t version = 0;
  std::shared_ptr<const MapKeyframes> keyframes;
};

// What one save did (Snapshot).
struct SaveOutcome {
  // Nothing to save by the time it ran: a save got there first, or the map was deleted.
  bool skipped = false;
  uint64_t version = 0;   // the version written
  int keyframes = 0;
  int64_t bytes = 0;      // the file's size
  absl::Duration took;    // writing it (after waiting for the file)
};

class MapStore {
 public:
  explicit MapStore(MapStoreOptions options);

  // Loads every <data_dir>/*.plx; files that fail to load are reported, not fatal.
  std::vector<std::string> LoadAllFromDataDir();
  // Removes the temporaries of saves interrupted by a crash (core/io/atomic_write.h
  // RemoveStaleTempFiles) from the data dir; the daemon logs each one.
  std::vector<StaleTempFile> RemoveStaleTempFiles();

  absl::StatusOr<MapStatus> Create(const std::string& name, float voxel_size);
  absl::StatusOr<MapStatus> Info(const std::string& name) const;
  std::vector<MapStatus> List() const;
  absl::StatusOr<MapVersion> Latest(const std::string& name) const;
  // Forgets the map and removes the file this store loaded it from or last saved it to (no
  // other: a file of the same name the store never read stays). When that file cannot be
  // removed the map is kept and the error returned, so it does not come back at the next start
  // after an OK.
  absl::Status Delete(const std::string& name);
  // Saves the newest version with its keyframes and version number (waiting for a save of the
  // map that is running first).
  absl::StatusOr<MapStatus> Save(const std::string& name);
  // Loads <data_dir>/<name>.plx; RESOURCE_EXHAUSTED before reading the payload when its header
  // says it needs more than max_map_bytes, or when the store is full.
  absl::StatusOr<MapStatus> Load(const std::string& name);
  // Saves every dirty map (drain), trying them all; returns those that could not be saved.
  std::vector<UnsavedMap> SaveDirty();
  // Names of the maps changed since they were last saved.
  std::vector<std::string> DirtyNames() const;
  // When the oldest change not on disk was made (InfiniteFuture: every map is saved).
  absl::Time OldestUnsavedChange() const;

  // Snapshots. The maps due at `now` by the snapshot rule (MapSaveState::SnapshotDue with
  // `interval`), each now claimed so it is not claimed again until Snapshot or ReleaseSnapshot
  // (one of which every claimed map gets). Nothing without a data dir.
  std::vector<std::string> ClaimDueSnapshots(absl::Duration interval, absl::Time now);
  // When the next map will be due (InfiniteFuture: none is dirty), claimed ones left out.
  absl::Time NextSnapshotDue(absl::Duration interval) const;
  // Saves a claimed map like Save; skipped when a save got there first and left nothing. A
  // failure is not retried before `retry_after` has passed.
  absl::StatusOr<SaveOutcome> Snapshot(const std::string& name, absl::Duration retry_after);
  // Gives a claim back unsaved (the snapshot's task was dropped: the daemon stops).
  void ReleaseSnapshot(const std::string& name);
  int64_t max_map_bytes() const { return options_.max_map_bytes; }

  // One mapping job per map: FAILED_PRECONDITION naming the holder when another holds the
  // lease.
  absl::Status BeginMapping(const std::string& name, MappingJobKind kind);
  void EndMapping(const std::string& name);
  // Publishes a new version; RESOURCE_EXHAUSTED over the memory limit. Only a lease holder
  // calls it (the Integrate stream, the SLAM job); the store does not check who calls, since
  // the lease belongs to a job, not to a caller it could recognise. `keyframes`: every keyframe
  // the version holds (the map's keyframe count becomes its size); null: the previous
  // version's list is kept and the count grows by `keyframes_added` (a publisher that keeps
  // no list; its keyframes are then not in the file).
  absl::StatusOr<uint64_t> Publish(const std::string& name,
                                   std::shared_ptr<const PlenoxelMap> map, int keyframes_added,
                                   std::shared_ptr<const MapKeyframes> keyframes = nullptr);

  int64_t TotalBytes() const;
  int size() const;

 private:
  struct Entry {
    std::shared_ptr<const PlenoxelMap> map;
    uint64_t version = 1;
    std::shared_ptr<const MapKeyframes> keyframes = std::make_shared<const MapKeyframes>();
    int keyframe_count = 0;
    MapSaveState save;             // unsaved changes, the save running
    bool snapshot_claimed = false;  // ClaimDueSnapshots, until Snapshot/ReleaseSnapshot
    bool mapping = false;
    MappingJobKind mapping_kind = MappingJobKind::kIntegrate;  // when `mapping`
    std::string file;  // the file this store loaded the map from or saved it to; empty: none
  };
  MapStatus StatusOf(const std::string& name, const Entry& e) const;
  // A map's file is touched by one operation at a time (save, snapshot, load, delete): a turn
  // waits until no other holds the name's, holds it while it lives, and is made and destroyed
  // without mutex_ held (it takes the lock itself).
  class FileTurn {
   public:
    FileTurn(MapStore* store, std::string name);
    ~FileTurn();
    FileTurn(const FileTurn&) = delete;
    FileTurn& operator=(const FileTurn&) = delete;

   private:
    MapStore* const store_;
    const std::string name_;
  };
  // Save and Snapshot.
  absl::StatusOr<SaveOutcome> SaveNewest(const std::string& name, bool snapshot,
                                         absl::Duration retry_after);
  std::string PathOf(const std::string& name) const;
  absl::StatusOr<Entry*> Find(const std::string& name);
  absl::StatusOr<const Entry*> Find(const std::string& name) const;

  MapStoreOptions options_;
  mutable std::mutex mutex_;
  std::map<std::string, Entry> maps_;
  std::set<std::string> file_busy_;    // names whose file an operation is working on
  std::condition_variable file_free_;  // one of them was given back
};

}  // namespace plx::server

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
//
// Shared storage (plenoxd --shared-dir, core/storage/map_storage.h) instead of a data dir: no
// map is loaded at start; a call that names a map the store does not hold (Info, Latest,
// BeginMapping, Delete) loads it from the storage first, and every map the store holds, made
// or loaded, is held under its lease (core/storage/lease_policy.h), renewed by RenewLeases
// (server/lease_keeper.h). Every save is a fenced write: the lease is checked against the
// token the map was taken under when the file is published, so a store whose lease was taken
// over writes nothing; it then drops the map, and calls naming it get the error that names
// the new owner's generation until the store can take the lease again.
//
// Handoff (core/storage/lease_policy.h, "Handoff"; server/map_store_handoff.cc): a call naming
// a map another daemon holds records a handoff request and gets UNAVAILABLE (clients retry);
// the holder's lease keeper calls HandOffWanted, which saves each requested map that is idle
// (no mapping job, no call naming it for handoff_quiet), drops it and releases its lease,
// reserved for the requester, whose retry then loads the file. Calls naming a map while it
// is being handed over get UNAVAILABLE. For two lease terms after this store lost a map to a
// takeover, calls naming it get the loss (FAILED_PRECONDITION naming the new generation)
// instead of a request: the new owner took it because this one stalled, and clients should
// see why.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "core/formats/map_file.h"
#include "core/formats/map_keyframe.h"
#include "core/formats/snapshot_policy.h"
#include "core/grid/map_status.h"
#include "core/grid/plenoxel_map.h"
#include "core/io/atomic_write.h"
#include "core/storage/map_storage.h"

namespace plx::server {

struct MapStoreOptions {
  std::string data_dir;               // empty: nothing is persisted
  int max_maps = 16;
  int64_t max_map_bytes = int64_t{4} << 30;
  // TEST ONLY (the stop watchdog's test, via $PLENOXD_TEST_ONLY_SAVE_DELAY_S in main.cc): every
  // save first sleeps this long, a save stuck on a hung file system. Zero in production.
  absl::Duration test_only_save_delay = absl::ZeroDuration();
  // Shared storage instead of data_dir (which is then empty); null: none. `holder` is this
  // store's lease holder id (MakeHolderId), `lease` the lease's terms, `clock` what lease
  // decisions read (tests move it by hand).
  std::shared_ptr<MapStorage> shared;
  std::string holder;
  LeaseTerms lease;
  std::function<absl::Time()> clock = [] { return absl::Now(); };
};

// A map whose lease could not be renewed (RenewLeases) or given back (ReleaseLeases); `lost`:
// another store took it over and this one dropped the map.
struct MapLeaseEvent {
  std::string name;
  absl::Status status;
  bool lost = false;
};

// A map HandOffWanted gave up (status OK) or tried to and kept (the save failed).
struct MapHandoffEvent {
  std::string name;
  std::string to;         // the requester's holder id
  absl::Status status;
  uint64_t version = 0;   // the version handed over
  bool saved = false;     // it had unsaved changes (or no file yet) and was saved first
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
  // The map as the save left it, taken under the store's lock before the file's turn ends (a
  // delete waiting for the turn may remove the map right after).
  MapStatus status;
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
  // Info and Latest load a map in shared storage that the store does not hold (see above).
  absl::StatusOr<MapStatus> Info(const std::string& name);
  std::vector<MapStatus> List() const;
  absl::StatusOr<MapVersion> Latest(const std::string& name);
  // Forgets the map and removes the file this store loaded it from or last saved it to (no
  // other: a file of the same name the store never read stays). When that file cannot be
  // removed the map is kept and the error returned, so it does not come back at the next start
  // after an OK.
  absl::Status Delete(const std::string& name);
  // Saves the newest version with its keyframes and version number (waiting for a save of the
  // map that is running first).
  absl::StatusOr<MapStatus> Save(const std::string& name);
  // Loads <data_dir>/<name>.plx (shared: the stored map, after taking its lease);
  // RESOURCE_EXHAUSTED before reading the payload when its header says it needs more than
  // max_map_bytes, or when the store is full.
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

  // Shared storage. Renews the lease of every map held (the lease keeper calls it every
  // LeaseTerms::renew_every); maps whose lease was taken over are dropped. Returns the maps
  // whose renewal failed.
  std::vector<MapLeaseEvent> RenewLeases();
  // Gives every lease up (the drain, after its save): another daemon may take the maps at
  // once. Nothing is written after it. Returns the maps whose lease could not be given back.
  std::vector<MapLeaseEvent> ReleaseLeases();
  bool shared() const { return options_.shared != nullptr; }
  int leases_held() const;
  // Maps dropped because another store took their lease over, and saves refused because the
  // lease they were written under was no longer this store's (nothing was published).
  int64_t lease_losses() const;
  int64_t fenced_saves_refused() const;
  // Handoff (the lease keeper calls it after RenewLeases, which notes the requests): gives up
  // every map another daemon asked for that is idle by ShouldHandOff. Returns what it did.
  std::vector<MapHandoffEvent> HandOffWanted();
  // Maps given up to a requester, and maps taken that had been released for this store.
  int64_t handoffs_given() const;
  int64_t handoffs_taken() const;

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
    uint64_t lease_token = 0;  // shared storage: the fencing token the map is held under
    // Not OK: the lease was taken over while a mapping job held the map; every call gets this
    // until the job ends (EndMapping), then the entry goes.
    absl::Status lost;
    // Handoff: when a call last named the map (lease clock), the daemon whose request the
    // last renewal found (empty: none), and, while the map is being handed over, to whom.
    absl::Time last_call = absl::InfinitePast();
    std::string wanted_by;
    std::string moving_to;
  };
  // A map file read, before it joins the store.
  struct LoadedFile {
    std::shared_ptr<const PlenoxelMap> map;
    std::shared_ptr<const MapKeyframes> keyframes;
    uint64_t saved_version = 0;
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
  // Why a name is not held: the lease loss that dropped it, or NotFound.
  absl::Status Missing(const std::string& name) const;
  absl::Status FullError() const;
  absl::StatusOr<LoadedFile> ReadFile(const std::string& path) const;
  // Puts a file read into the store (mutex_ held): a new entry, or the held one replaced.
  absl::StatusOr<MapStatus> Install(const std::string& name, LoadedFile file,
                                    const std::string& path, uint64_t lease_token);
  // Shared storage: loads `name` if it is stored and not held (OK when it is not stored:
  // the caller's lookup then says so).
  absl::Status HoldShared(const std::string& name);
  absl::StatusOr<MapStatus> LoadShared(const std::string& name, bool only_if_absent);
  absl::Status SaveShared(const std::string& name, uint64_t token, const PlenoxelMap& map,
                          const MapFileState& state);
  // The lease of `name` was taken over (mutex_ held): the map goes (or, while a mapping job
  // holds it, turns into a tombstone) and `why` answers calls naming it.
  void DropLost(const std::string& name, const absl::Status& why);
  // Whether this store lost `name` to a takeover less than two lease terms ago (mutex_ held).
  bool RecentlyLost(const std::string& name, absl::Time now) const;
  // Shared storage, `name` not stored: asks its live holder for it (HandoffRequestedError), or
  // OK when nobody else holds it.
  absl::Status RequestUnsaved(const std::string& name);
  // Whether `e` is a map another daemon asked for that may go now: held, not already moving,
  // and idle by ShouldHandOff (mutex_ held).
  bool HandOffDue(const Entry& e, absl::Time now) const;
  // Gives `name` up to its requester (map_store_handoff.cc); nullopt when it no longer
  // qualifies.
  std::optional<MapHandoffEvent> HandOff(const std::string& name);

  MapStoreOptions options_;
  mutable std::mutex mutex_;
  std::map<std::string, Entry> maps_;
  std::set<std::string> file_busy_;    // names whose file an operation is working on
  std::condition_variable file_free_;  // one of them was given back
  // Maps dropped by DropLost: why, and when by the lease clock.
  struct LostMap {
    absl::Status why;
    absl::Time at;
  };
  std::map<std::string, LostMap> lost_;
  int64_t lease_losses_ = 0;
  int64_t fenced_saves_refused_ = 0;
  int64_t handoffs_given_ = 0;
  int64_t handoffs_taken_ = 0;
};

}  // namespace plx::server

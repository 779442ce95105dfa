// Shared map storage (plenoxd --shared-dir): where several daemons keep map files and the
// maps' leases (core/storage/lease_policy.h), so any of them can load a map another saved.
//
// The interface is kept to what an object store can do as well as a directory, so one can be
// added without touching the daemon:
//   - objects: List, Stat, LocalPath (a local file holding a map's bytes, for LoadMapFile: the
//     directory's own file; an object store downloads to a cache file first);
//   - a fenced write (WriteFenced): the caller writes a complete file at a local path it is
//     given (SaveMap streams gigabytes, so no object is held in memory), and the storage
//     publishes it in one atomic step only if the caller's lease check still passes on the
//     lease record at that moment;
//   - lease records with compare-and-swap on a revision (SwapLease).
// The directory (core/storage/directory_storage.h) runs the check under an flock of the map's
// lock file, just before rename(2). An object store (S3 or GCS with conditional writes)
// would keep each lease as a small object and use its generation (GCS) or ETag (S3) as the
// revision: SwapLease is a PUT with `If-Match` (`x-goog-if-generation-match`), and a fenced
// write uploads the file as an immutable object named by token and version, then swaps the
// lease record (If-Match) to point at it; a fenced owner's swap fails its precondition, so its
// upload is never read (and is collected later). No other call needs more than a GET or LIST.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/storage/lease_policy.h"

namespace plx {

struct StoredMapInfo {
  std::string name;
  int64_t bytes = 0;
  absl::Time modified = absl::InfinitePast();
};

class MapStorage {
 public:
  // Runs on the lease record as stored when a write commits; OK lets it commit.
  using LeaseCheck = std::function<absl::Status(const LeaseRecord& current)>;
  // Writes a complete file at `path` (a local path the storage chose), e.g. SaveMap.
  using FileWriter = std::function<absl::Status(const std::string& path)>;

  virtual ~MapStorage() = default;

  // For logs and errors: "dir /mnt/plenoxd".
  virtual std::string Describe() const = 0;
  // The names of the stored maps (not leases or temporaries), sorted.
  virtual absl::StatusOr<std::vector<std::string>> List() const = 0;
  // NotFound when `name` is not stored.
  virtual absl::StatusOr<StoredMapInfo> Stat(const std::string& name) const = 0;
  // A local file holding `name`'s current bytes (NotFound when not stored). A new version
  // replaces the file atomically, so a reader that opened it keeps reading one version.
  virtual absl::StatusOr<std::string> LocalPath(const std::string& name) = 0;

  // Publishes a new `name`: `may_write` is run on the stored lease record first (a refusal
  // writes nothing), then `write` fills a staging file, then `may_write` is run again on the
  // record as it is when the file is published, atomically with publishing it: a refusal then
  // leaves the stored file as it was and removes the staging file. Returns the refusal as is.
  virtual absl::Status WriteFenced(const std::string& name, const LeaseCheck& may_write,
                                   const FileWriter& write) = 0;
  // Removes `name` (NotFound is OK) under the same check. Its lease record stays, so tokens
  // keep growing if the name is used again.
  virtual absl::Status RemoveFenced(const std::string& name, const LeaseCheck& may_write) = 0;

  // `name`'s lease record; a record with token 0 and revision 0 when it was never held.
  // DataLoss when the stored record is damaged.
  virtual absl::StatusOr<LeaseRecord> ReadLease(const std::string& name) = 0;
  // Stores `next` if the stored record's revision is still `expected_revision` (0: none is
  // stored); ABORTED when it changed meanwhile (another writer came first). Returns the record
  // as stored, with its new revision.
  virtual absl::StatusOr<LeaseRecord> SwapLease(const std::string& name,
                                                uint64_t expected_revision,
                                                const LeaseRecord& next) = 0;
};

// Takes or renews `name`'s lease for `holder` (NextLease on the stored record, then SwapLease;
// a lost race is read and decided again, a few times). `held_token`: the token the caller
// holds it under, 0 for none. Returns the record now stored.
absl::StatusOr<LeaseRecord> AcquireLease(MapStorage& storage, const std::string& name,
                                         const std::string& holder, uint64_t held_token,
                                         const std::function<absl::Time()>& clock,
                                         const LeaseTerms& terms);

// Records `requester`'s handoff request in `name`'s lease record (RequestHandoff, then
// SwapLease; a lost race is decided again). Returns the record stored, or RequestHandoff's
// refusal (FAILED_PRECONDITION: free or the requester's own; UNAVAILABLE: reserved for
// another).
absl::StatusOr<LeaseRecord> RecordHandoffRequest(MapStorage& storage, const std::string& name,
                                                 const std::string& requester,
                                                 const std::function<absl::Time()>& clock,
                                                 const LeaseTerms& terms);

// Takes `name`'s lease for `holder` like AcquireLease (holding nothing); when another daemon
// holds it live, records `holder`'s handoff request instead and returns HandoffRequestedError
// (UNAVAILABLE, IsHandoffRequested). A lease reserved for another requester is UNAVAILABLE
// too, with nothing stored. `handed_over` (optional): set when the lease taken had been
// released for `holder`'s own request.
absl::StatusOr<LeaseRecord> TakeOrRequestLease(MapStorage& storage, const std::string& name,
                                               const std::string& holder,
                                               const std::function<absl::Time()>& clock,
                                               const LeaseTerms& terms,
                                               bool* handed_over = nullptr);

// Gives `name`'s lease up if `holder` still holds it under `token` (ReleasedLease); OK when
// it does not (nothing to give up).
absl::Status ReleaseLease(MapStorage& storage, const std::string& name,
                          const std::string& holder, uint64_t token);

}  // namespace plx

// MapStorage in a directory on a shared volume (plenoxd --shared-dir: NFS, CephFS, a
// Kubernetes ReadWriteMany volume, or one machine's disk for daemons side by side).
//
// Per map <name>:
//   <name>.plx                      the map file (core/formats/map_file.h)
//   <name>.plx.lease                its lease record (text, replaced atomically by rename),
//                                   with a pending handoff request when there is one
//   <name>.plx.lock                 never replaced; flock(2)ed around every lease swap and
//                                   every commit, so a check and what it allows are one step
//   <name>.plx.stage.<writer id>    a new version being written (with SaveMap's own
//                                   "<staging>.tmp.<pid>" inside it); writer ids include the
//                                   host, the pid and a random part, since pids repeat across
//                                   machines
//
// A fenced write fills its staging file, takes the lock, reads the lease record, runs the
// caller's check and renames the staging file over <name>.plx (then fsyncs the directory);
// a lease swap takes the same lock. A process paused inside that critical section (a few
// milliseconds) holds the lock while it is stopped: others then wait up to lock_timeout and
// give up with UNAVAILABLE, and never write meanwhile. On NFS, flock is carried by the
// server's byte-range locks (Linux NFS clients since 2.6.12); a file system without working
// locks must not be used.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/time/time.h"
#include "core/io/atomic_write.h"
#include "core/storage/map_storage.h"

namespace plx {

struct DirectoryStorageOptions {
  std::string dir;  // must exist
  // How long a lease swap or commit waits for another process's hold of a map's lock file.
  absl::Duration lock_timeout = absl::Seconds(10);
  // Tells this writer's staging files from other processes' (MakeHolderId); required.
  std::string writer_id;
};

class DirectoryMapStorage final : public MapStorage {
 public:
  explicit DirectoryMapStorage(DirectoryStorageOptions options);

  std::string Describe() const override;
  absl::StatusOr<std::vector<std::string>> List() const override;
  absl::StatusOr<StoredMapInfo> Stat(const std::string& name) const override;
  absl::StatusOr<std::string> LocalPath(const std::string& name) override;
  absl::Status WriteFenced(const std::string& name, const LeaseCheck& may_write,
                           const FileWriter& write) override;
  absl::Status RemoveFenced(const std::string& name, const LeaseCheck& may_write) override;
  absl::StatusOr<LeaseRecord> ReadLease(const std::string& name) override;
  absl::StatusOr<LeaseRecord> SwapLease(const std::string& name, uint64_t expected_revision,
                                        const LeaseRecord& next) override;

  // Removes staging files (any writer's, with SaveMap's temporaries inside them) last changed
  // before `now - older_than`: left by a writer that died between writing and publishing. A
  // live writer changes its file as it writes, so give it far longer than a save takes.
  std::vector<StaleTempFile> RemoveStaleStaging(absl::Duration older_than, absl::Time now);

  std::string MapPath(const std::string& name) const;
  std::string LeasePath(const std::string& name) const;

 private:
  class FileLock;
  absl::StatusOr<FileLock> Lock(const std::string& name) const;

  DirectoryStorageOptions options_;
};

}  // namespace plx

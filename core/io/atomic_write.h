// Writing files so that readers never see half of them: each file goes to a temporary name next
// to it, is flushed to disk, and is renamed into place only when every file of the set was
// written; on any failure no temporary is left and no target is touched (targets renamed before
// a failed rename stay replaced: rename is atomic per file, not per set).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace plx {

// NotFound naming `what` unless the folder `path` would be written into exists (writers that
// stream large files themselves check this before doing any work).
absl::Status CheckParentDirectory(const std::string& path, const std::string& what);

// Makes a rename into the folder of `path` durable (fsync of the folder). Best effort: some file
// systems refuse fsync on directories, and the file is complete and in place by then.
void SyncParentDirectory(const std::string& path);

// The one errno -> Status mapping of file writes: NotFound (ENOENT), PermissionDenied (EACCES,
// EPERM, EROFS), ResourceExhausted (ENOSPC, EDQUOT, EFBIG), Unavailable (other I/O errors).
absl::Status FileWriteError(int err, const std::string& message);

// One file written under a temporary name next to its target, made durable (fsync) and renamed
// into place by Commit; a writer destroyed before Commit removes its temporary, so a failed
// write never leaves a partial target. Streaming writers (map files) write through fd().
class AtomicFileWriter {
 public:
  // `what` prefixes every error. `keep_extension`: the temporary ends with the target's
  // extension (viewers and editors see the right type); false keeps it out of globs for that
  // extension (the daemon loads every *.plx of its data dir).
  static absl::StatusOr<AtomicFileWriter> Open(const std::string& path, const std::string& what,
                                               bool keep_extension = true);
  AtomicFileWriter(AtomicFileWriter&& other) noexcept;
  AtomicFileWriter& operator=(AtomicFileWriter&&) = delete;
  ~AtomicFileWriter();

  int fd() const { return fd_; }
  const std::string& temp_path() const { return temp_path_; }
  // Writes all of `bytes`, retrying short writes and EINTR.
  absl::Status Write(absl::string_view bytes);
  // Flushes the contents to disk and closes the temporary (still under its temporary name).
  absl::Status Finish();
  // Renames the finished temporary onto the target (atomic), then syncs the folder.
  absl::Status Commit();

 private:
  AtomicFileWriter(std::string path, std::string temp_path, std::string what, int fd);

  std::string path_, temp_path_, what_;
  int fd_ = -1;
  bool committed_ = false;
};

// A temporary of AtomicFileWriter ("<target>.tmp.<pid>", or "<target>.tmp.<pid><ext>" with
// the target's extension <ext>) whose writer died before Commit: a crash or kill during a save.
struct StaleTempFile {
  std::string path;
  int64_t pid = 0;
  absl::Status removed;  // OK, or why it could not be removed
};

// Removes the temporaries in `dir` (not its subfolders) of targets with `target_extension`
// (".plx": "<name>.plx.tmp.<pid>") that are regular files and whose pid is not a running
// process (this process counts as running, as does a pid we may not signal), and reports each
// one. A pid reused by an unrelated process keeps its file until a later call.
std::vector<StaleTempFile> RemoveStaleTempFiles(const std::string& dir,
                                                const std::string& target_extension);

// `files`: (path, bytes). Errors name `what` and the file: NotFound when a target's directory
// does not exist, PermissionDenied for access errors, Unavailable for other I/O errors.
absl::Status WriteFilesAtomically(const std::vector<std::pair<std::string, std::string>>& files,
                                  const std::string& what);

inline absl::Status WriteFileAtomically(const std::string& path, const std::string& bytes,
                                        const std::string& what) {
  return WriteFilesAtomically({{path, bytes}}, what);
}

}  // namespace plx

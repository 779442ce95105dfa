// Writing files so that readers never see half of them: each file goes to a temporary name next
// to it, is flushed to disk, and is renamed into place only when every file of the set was
// written; on any failure no temporary is left and no target is touched (targets renamed before
// a failed rename stay replaced: rename is atomic per file, not per set).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"

namespace plx {

// NotFound naming `what` unless the folder `path` would be written into exists (writers that
// stream large files themselves check this before doing any work).
absl::Status CheckParentDirectory(const std::string& path, const std::string& what);

// Makes a rename into the folder of `path` durable (fsync of the folder). Best effort: some file
// systems refuse fsync on directories, and the file is complete and in place by then.
void SyncParentDirectory(const std::string& path);

// `files`: (path, bytes). Errors name `what` and the file: NotFound when a target's directory
// does not exist, PermissionDenied for access errors, Unavailable for other I/O errors.
absl::Status WriteFilesAtomically(const std::vector<std::pair<std::string, std::string>>& files,
                                  const std::string& what);

inline absl::Status WriteFileAtomically(const std::string& path, const std::string& bytes,
                                        const std::string& what) {
  return WriteFilesAtomically({{path, bytes}}, what);
}

}  // namespace plx

#include "core/storage/directory_storage.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/time/clock.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

namespace fs = std::filesystem;

constexpr char kLeaseMagic[] = "plenoxd-lease 1";
constexpr char kStagingMarker[] = ".plx.stage.";
// Lease records are a few lines; anything much larger is not one.
constexpr int64_t kMaxLeaseBytes = 4096;

std::string LeaseText(const LeaseRecord& r) {
  std::string text = absl::StrCat(kLeaseMagic, "\nholder ", r.holder, "\ntoken ", r.token,
                                  "\nexpires_unix_ns ", absl::ToUnixNanos(r.expires),
                                  "\nrevision ", r.revision, "\n");
  // Only while a handoff is pending; records without these lines have none.
  if (!r.wanted_by.empty()) {
    absl::StrAppend(&text, "wanted_by ", r.wanted_by, "\nwanted_until_unix_ns ",
                    absl::ToUnixNanos(r.wanted_until), "\n");
  }
  return text;
}

absl::StatusOr<LeaseRecord> ParseLease(const std::string& text, const std::string& path) {
  const auto damaged = [&](absl::string_view why) {
    return absl::DataLossError(absl::StrCat("lease record ", path, " is damaged: ", why));
  };
  std::vector<std::string> lines = absl::StrSplit(text, '\n', absl::SkipEmpty());
  if (lines.empty() || lines[0] != kLeaseMagic) return damaged("not a plenoxd lease");
  LeaseRecord r;
  bool holder = false, token = false, expires = false, revision = false;
  for (size_t i = 1; i < lines.size(); ++i) {
    const size_t space = lines[i].find(' ');
    const std::string key = lines[i].substr(0, space);
    const std::string value = space == std::string::npos ? "" : lines[i].substr(space + 1);
    int64_t ns = 0;
    if (key == "holder") {
      r.holder = value;
      holder = true;
    } else if (key == "token") {
      token = absl::SimpleAtoi(value, &r.token);
      if (!token) return damaged("token is not a number");
    } else if (key == "expires_unix_ns") {
      expires = absl::SimpleAtoi(value, &ns);
      if (!expires) return damaged("expires_unix_ns is not a number");
      r.expires = absl::FromUnixNanos(ns);
    } else if (key == "revision") {
      revision = absl::SimpleAtoi(value, &r.revision);
      if (!revision) return damaged("revision is not a number");
    } else if (key == "wanted_by") {
      r.wanted_by = value;
    } else if (key == "wanted_until_unix_ns") {
      if (!absl::SimpleAtoi(value, &ns)) return damaged("wanted_until_unix_ns is not a number");
      r.wanted_until = absl::FromUnixNanos(ns);
    }
  }
  if (!holder || !token || !expires || !revision) return damaged("a field is missing");
  return r;
}

}  // namespace

// An flock(2) on a map's lock file, released (and the file closed) when destroyed.
class DirectoryMapStorage::FileLock {
 public:
  explicit FileLock(int fd) : fd_(fd) {}
  FileLock(FileLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  FileLock& operator=(FileLock&&) = delete;
  ~FileLock() {
    if (fd_ < 0) return;
    ::flock(fd_, LOCK_UN);
    ::close(fd_);
  }

 private:
  int fd_;
};

DirectoryMapStorage::DirectoryMapStorage(DirectoryStorageOptions options)
    : options_(std::move(options)) {}

std::string DirectoryMapStorage::Describe() const { return "dir " + options_.dir; }

std::string DirectoryMapStorage::MapPath(const std::string& name) const {
  return (fs::path(options_.dir) / (name + ".plx")).string();
}

std::string DirectoryMapStorage::LeasePath(const std::string& name) const {
  return MapPath(name) + ".lease";
}

absl::StatusOr<DirectoryMapStorage::FileLock> DirectoryMapStorage::Lock(
    const std::string& name) const {
  const std::string path = MapPath(name) + ".lock";
  // O_NONBLOCK: a FIFO planted at the name fails the open instead of blocking it.
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NONBLOCK, 0644);
  if (fd < 0) return FileWriteError(errno, absl::StrCat("opening lock file ", path));
  FileLock lock(fd);
  struct stat st;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    return absl::FailedPreconditionError(absl::StrCat(path, " is not a regular file"));
  }
  // Polled rather than blocking: a holder paused inside its few milliseconds would otherwise
  // block this thread for as long as it stays paused.
  const absl::Time deadline = absl::Now() + options_.lock_timeout;
  for (;;) {
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) return std::move(lock);
    const int err = errno;
    if (err == EINTR) continue;
    if (err != EWOULDBLOCK) return FileWriteError(err, absl::StrCat("locking ", path));
    if (absl::Now() >= deadline) {
      return absl::UnavailableError(absl::StrCat(
          "map \"", name, "\": ", path, " stayed locked by another process for ",
          absl::FormatDuration(options_.lock_timeout),
          " (a daemon paused inside a lease swap or commit?); nothing was written"));
    }
    absl::SleepFor(absl::Milliseconds(2));
  }
}

absl::StatusOr<std::vector<std::string>> DirectoryMapStorage::List() const {
  std::vector<std::string> names;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(options_.dir, ec)) {
    std::error_code type_ec;
    if (entry.path().extension() != ".plx" || !entry.is_regular_file(type_ec)) continue;
    names.push_back(entry.path().stem().string());
  }
  if (ec) return absl::UnavailableError(absl::StrCat("listing ", options_.dir, ": ", ec.message()));
  std::sort(names.begin(), names.end());
  return names;
}

absl::StatusOr<StoredMapInfo> DirectoryMapStorage::Stat(const std::string& name) const {
  const std::string path = MapPath(name);
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    const int err = errno;
    if (err == ENOENT) {
      return absl::NotFoundError(absl::StrCat("map \"", name, "\" is not in ", Describe()));
    }
    return FileWriteError(err, absl::StrCat("stat of ", path));
  }
  if (!S_ISREG(st.st_mode)) {
    return absl::FailedPreconditionError(absl::StrCat(path, " is not a regular file"));
  }
  return StoredMapInfo{name, static_cast<int64_t>(st.st_size), absl::TimeFromTimespec(st.st_mtim)};
}

absl::StatusOr<std::string> DirectoryMapStorage::LocalPath(const std::string& name) {
  PLX_RETURN_IF_ERROR(Stat(name).status());
  return MapPath(name);
}

absl::Status DirectoryMapStorage::WriteFenced(const std::string& name,
                                              const LeaseCheck& may_write,
                                              const FileWriter& write) {
  // Checked before the work too: a fenced owner does not even write its staging file.
  PLX_ASSIGN_OR_RETURN(const LeaseRecord before, ReadLease(name));
  PLX_RETURN_IF_ERROR(may_write(before));
  const std::string target = MapPath(name);
  const std::string staging = absl::StrCat(target, ".stage.", options_.writer_id);
  struct RemoveStaging {
    const std::string& path;
    ~RemoveStaging() { ::unlink(path.c_str()); }  // ENOENT once it was renamed into place
  } remove_staging{staging};
  PLX_RETURN_IF_ERROR(write(staging));
  PLX_ASSIGN_OR_RETURN(const FileLock lock, Lock(name));
  // The check that counts: the record as it is now, and nobody can change it before the
  // rename below (every swap takes the same lock).
  PLX_ASSIGN_OR_RETURN(const LeaseRecord current, ReadLease(name));
  PLX_RETURN_IF_ERROR(may_write(current));
  if (::rename(staging.c_str(), target.c_str()) != 0) {
    return FileWriteError(errno, absl::StrCat("map \"", name, "\": renaming ", staging, " to ",
                                              target));
  }
  SyncParentDirectory(target);
  return absl::OkStatus();
}

absl::Status DirectoryMapStorage::RemoveFenced(const std::string& name,
                                               const LeaseCheck& may_write) {
  PLX_ASSIGN_OR_RETURN(const FileLock lock, Lock(name));
  PLX_ASSIGN_OR_RETURN(const LeaseRecord current, ReadLease(name));
  PLX_RETURN_IF_ERROR(may_write(current));
  const std::string target = MapPath(name);
  if (::unlink(target.c_str()) != 0 && errno != ENOENT) {
    return FileWriteError(errno, absl::StrCat("map \"", name, "\": removing ", target));
  }
  SyncParentDirectory(target);
  return absl::OkStatus();
}

absl::StatusOr<LeaseRecord> DirectoryMapStorage::ReadLease(const std::string& name) {
  const std::string path = LeasePath(name);
  // Only regular files (never blocking on a FIFO), and only a few KB.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const int err = errno;
    if (err == ENOENT) return LeaseRecord{};
    return FileWriteError(err, absl::StrCat("reading lease record ", path));
  }
  struct stat st;
  const bool regular = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  std::string text;
  if (regular && st.st_size <= kMaxLeaseBytes) {
    text.resize(static_cast<size_t>(kMaxLeaseBytes));
    const ssize_t n = ::pread(fd, text.data(), text.size(), 0);
    text.resize(n > 0 ? static_cast<size_t>(n) : 0);
  }
  ::close(fd);
  if (!regular || st.st_size > kMaxLeaseBytes) {
    return absl::DataLossError(
        absl::StrCat("lease record ", path, " is not a regular file of at most ",
                     kMaxLeaseBytes, " bytes"));
  }
  return ParseLease(text, path);
}

absl::StatusOr<LeaseRecord> DirectoryMapStorage::SwapLease(const std::string& name,
                                                           uint64_t expected_revision,
                                                           const LeaseRecord& next) {
  PLX_ASSIGN_OR_RETURN(const FileLock lock, Lock(name));
  PLX_ASSIGN_OR_RETURN(const LeaseRecord current, ReadLease(name));
  if (current.revision != expected_revision) {
    return absl::AbortedError(absl::StrCat("map \"", name, "\": lease record changed (revision ",
                                           current.revision, ", expected ", expected_revision,
                                           ")"));
  }
  LeaseRecord stored = next;
  stored.revision = current.revision + 1;
  // Under the lock, so this process is the only writer of the record's temporary.
  PLX_RETURN_IF_ERROR(WriteFileAtomically(LeasePath(name), LeaseText(stored),
                                          absl::StrCat("lease of map \"", name, "\"")));
  return stored;
}

std::vector<StaleTempFile> DirectoryMapStorage::RemoveStaleStaging(absl::Duration older_than,
                                                                   absl::Time now) {
  std::vector<StaleTempFile> removed;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(options_.dir, ec)) {
    const std::string file = entry.path().filename().string();
    if (file.find(kStagingMarker) == std::string::npos) continue;
    struct stat st;
    // lstat: a link is not ours to remove, whatever it points to.
    if (::lstat(entry.path().c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
    if (absl::TimeFromTimespec(st.st_mtim) > now - older_than) continue;
    StaleTempFile stale{entry.path().string(), 0, absl::OkStatus()};
    if (::unlink(stale.path.c_str()) != 0 && errno != ENOENT) {
      stale.removed = FileWriteError(errno, absl::StrCat("removing ", stale.path));
    }
    removed.push_back(std::move(stale));
  }
  return removed;
}

}  // namespace plx

#include "core/io/atomic_write.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <limits>
#include <system_error>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace plx {
namespace {

namespace fs = std::filesystem;

// The temporary keeps the target's extension unless asked not to (see AtomicFileWriter).
std::string TempPath(const std::string& path, bool keep_extension) {
  return absl::StrCat(path, ".tmp.", ::getpid(),
                      keep_extension ? fs::path(path).extension().string() : std::string());
}

// The pid of a name TempPath made for a target ending in `target_extension`
// ("<target>.tmp.<pid>" or "<target>.tmp.<pid><ext>", <ext> being the target's extension), or 0
// for any other name.
int64_t TempFilePid(const std::string& name, const std::string& target_extension) {
  const size_t at = name.rfind(".tmp.");
  if (at == std::string::npos || at == 0) return 0;
  const std::string target = name.substr(0, at);
  if (fs::path(target).extension() != target_extension) return 0;
  size_t end = at + 5;
  int64_t pid = 0;
  while (end < name.size() && name[end] >= '0' && name[end] <= '9' && pid < (int64_t{1} << 40)) {
    pid = pid * 10 + (name[end] - '0');
    ++end;
  }
  if (end == at + 5 || pid <= 0) return 0;
  const std::string rest = name.substr(end);
  if (!rest.empty() && rest != fs::path(target).extension().string()) return 0;
  return pid;
}

bool ProcessIsRunning(int64_t pid) {
  if (pid == ::getpid()) return true;
  if (pid > std::numeric_limits<pid_t>::max()) return false;
  // Signal 0 checks existence only; EPERM means it exists but is not ours to signal.
  return ::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

}  // namespace

std::vector<StaleTempFile> RemoveStaleTempFiles(const std::string& dir,
                                                const std::string& target_extension) {
  std::vector<StaleTempFile> stale;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    const int64_t pid = TempFilePid(entry.path().filename().string(), target_extension);
    if (pid == 0) continue;
    std::error_code type_ec;
    // symlink_status: a link is not ours to remove, whatever it points to.
    if (!fs::is_regular_file(entry.symlink_status(type_ec)) || ProcessIsRunning(pid)) continue;
    StaleTempFile file{entry.path().string(), pid, absl::OkStatus()};
    if (::unlink(file.path.c_str()) != 0) {
      const int err = errno;
      if (err != ENOENT) file.removed = FileWriteError(err, absl::StrCat("removing ", file.path));
    }
    stale.push_back(std::move(file));
  }
  return stale;
}

absl::Status CheckParentDirectory(const std::string& path, const std::string& what) {
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return absl::NotFoundError(absl::StrCat(what, ": directory ", dir.string(), " does not exist"));
  }
  return absl::OkStatus();
}

void SyncParentDirectory(const std::string& path) {
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

absl::Status FileWriteError(int err, const std::string& message) {
  const std::string text = absl::StrCat(message, ": ", std::strerror(err));
  if (err == ENOENT) return absl::NotFoundError(text);
  if (err == EACCES || err == EPERM || err == EROFS) return absl::PermissionDeniedError(text);
  if (err == ENOSPC || err == EDQUOT || err == EFBIG) return absl::ResourceExhaustedError(text);
  return absl::UnavailableError(text);
}

absl::StatusOr<AtomicFileWriter> AtomicFileWriter::Open(const std::string& path,
                                                        const std::string& what,
                                                        bool keep_extension) {
  if (absl::Status s = CheckParentDirectory(path, what); !s.ok()) return s;
  std::string temp = TempPath(path, keep_extension);
  // O_NONBLOCK: something other than a regular file already at the temporary's name (a FIFO)
  // must fail the write, not block it (a FIFO without a reader gives ENXIO at once).
  const int fd =
      ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NONBLOCK, 0644);
  if (fd < 0) return FileWriteError(errno, absl::StrCat(what, ": cannot create temp file ", temp));
  struct stat st;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);  // not ours to remove: the writer below would unlink it
    return absl::FailedPreconditionError(
        absl::StrCat(what, ": temp file ", temp, " exists and is not a regular file"));
  }
  return AtomicFileWriter(path, std::move(temp), what, fd);
}

AtomicFileWriter::AtomicFileWriter(std::string path, std::string temp_path, std::string what,
                                   int fd)
    : path_(std::move(path)), temp_path_(std::move(temp_path)), what_(std::move(what)), fd_(fd) {}

AtomicFileWriter::AtomicFileWriter(AtomicFileWriter&& other) noexcept
    : path_(std::move(other.path_)),
      temp_path_(std::move(other.temp_path_)),
      what_(std::move(other.what_)),
      fd_(std::exchange(other.fd_, -1)),
      committed_(std::exchange(other.committed_, true)) {}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_) ::unlink(temp_path_.c_str());
}

absl::Status AtomicFileWriter::Write(absl::string_view data) {
  while (!data.empty()) {
    const ssize_t n = ::write(fd_, data.data(), data.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return FileWriteError(errno, absl::StrCat(what_, ": writing ", temp_path_));
    }
    data.remove_prefix(static_cast<size_t>(n));
  }
  return absl::OkStatus();
}

absl::Status AtomicFileWriter::Finish() {
  // Contents must be on disk before the rename publishes them, or a crash could leave a
  // complete name pointing at incomplete contents.
  absl::Status status;
  if (::fsync(fd_) != 0) {
    status = FileWriteError(errno, absl::StrCat(what_, ": fsync of ", temp_path_));
  }
  const int closed = ::close(fd_);
  fd_ = -1;
  if (closed != 0 && status.ok()) {
    status = FileWriteError(errno, absl::StrCat(what_, ": closing ", temp_path_));
  }
  return status;
}

absl::Status AtomicFileWriter::Commit() {
  if (::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    return FileWriteError(errno,
                          absl::StrCat(what_, ": renaming ", temp_path_, " to ", path_));
  }
  committed_ = true;
  SyncParentDirectory(path_);
  return absl::OkStatus();
}

absl::Status WriteFilesAtomically(const std::vector<std::pair<std::string, std::string>>& files,
                                  const std::string& what) {
  for (const auto& file : files) {
    if (absl::Status s = CheckParentDirectory(file.first, what); !s.ok()) return s;
  }
  // Every file is written and made durable before the first rename; a failure before then
  // leaves no target touched (the writers remove their temporaries).
  std::vector<AtomicFileWriter> writers;
  writers.reserve(files.size());
  for (const auto& [path, bytes] : files) {
    absl::StatusOr<AtomicFileWriter> writer = AtomicFileWriter::Open(path, what);
    if (!writer.ok()) return writer.status();
    writers.push_back(*std::move(writer));
    if (absl::Status s = writers.back().Write(bytes); !s.ok()) return s;
    if (absl::Status s = writers.back().Finish(); !s.ok()) return s;
  }
  for (AtomicFileWriter& writer : writers) {
    if (absl::Status s = writer.Commit(); !s.ok()) return s;
  }
  return absl::OkStatus();
}

}  // namespace plx

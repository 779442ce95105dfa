#include "core/io/atomic_write.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace plx {
namespace {

namespace fs = std::filesystem;

absl::Status ErrnoStatus(int err, const std::string& message) {
  const std::string text = absl::StrCat(message, ": ", std::strerror(err));
  if (err == ENOENT) return absl::NotFoundError(text);
  if (err == EACCES || err == EPERM || err == EROFS) return absl::PermissionDeniedError(text);
  return absl::UnavailableError(text);
}

// Writes all of `data` to `fd`, retrying short writes and EINTR.
absl::Status WriteAll(int fd, absl::string_view data, const std::string& what) {
  while (!data.empty()) {
    const ssize_t n = ::write(fd, data.data(), data.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return ErrnoStatus(errno, what);
    }
    data.remove_prefix(static_cast<size_t>(n));
  }
  return absl::OkStatus();
}

// The temporary keeps the target's extension, so tools that look at it (image viewers, editors)
// see the right type while it is being written.
std::string TempPath(const std::string& path) {
  return absl::StrCat(path, ".tmp.", ::getpid(), fs::path(path).extension().string());
}

absl::Status WriteTemp(const std::string& temp, const std::string& bytes, const std::string& what) {
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return ErrnoStatus(errno, absl::StrCat(what, ": cannot create temp file ", temp));
  absl::Status status = WriteAll(fd, bytes, absl::StrCat(what, ": writing ", temp));
  // Contents must be on disk before the rename publishes them.
  if (status.ok() && ::fsync(fd) != 0) {
    status = ErrnoStatus(errno, absl::StrCat(what, ": fsync of ", temp));
  }
  if (::close(fd) != 0 && status.ok()) {
    status = ErrnoStatus(errno, absl::StrCat(what, ": closing ", temp));
  }
  return status;
}

}  // namespace

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

absl::Status WriteFilesAtomically(const std::vector<std::pair<std::string, std::string>>& files,
                                  const std::string& what) {
  for (const auto& file : files) {
    if (absl::Status s = CheckParentDirectory(file.first, what); !s.ok()) return s;
  }
  std::vector<std::string> temps;
  const auto remove_temps = [&] {
    for (const std::string& temp : temps) ::unlink(temp.c_str());
  };
  for (const auto& [path, bytes] : files) {
    temps.push_back(TempPath(path));
    if (absl::Status s = WriteTemp(temps.back(), bytes, what); !s.ok()) {
      remove_temps();
      return s;
    }
  }
  for (size_t i = 0; i < files.size(); ++i) {
    if (::rename(temps[i].c_str(), files[i].first.c_str()) != 0) {
      const absl::Status s =
          ErrnoStatus(errno, absl::StrCat(what, ": renaming ", temps[i], " to ", files[i].first));
      remove_temps();
      return s;
    }
  }
  for (const auto& file : files) SyncParentDirectory(file.first);
  return absl::OkStatus();
}

}  // namespace plx

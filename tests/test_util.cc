#include "tests/test_util.h"

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

namespace plx::testing {

std::string SharedDataDir() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("PLX_DATA_DIR"); env != nullptr && fs::is_directory(env)) {
    return env;
  }
#ifdef PLX_SHARED_DATA_DIR
  if (fs::is_directory(PLX_SHARED_DATA_DIR)) return PLX_SHARED_DATA_DIR;
#endif
  return "";
}

std::string SharedSequence(const std::string& name) {
  const std::string root = SharedDataDir();
  if (root.empty()) return "";
  const std::string path = root + "/" + name;
  return std::filesystem::is_directory(path) ? path : "";
}

namespace {

// The directories MakeTempDir made, removed when the test binary exits, so that runs do not
// pile scratch folders up in the temp dir. PLX_KEEP_TEST_DIRS=1 keeps them to look at. Only
// the process that made them removes them (a forked child that exits normally must not).
class TempDirs {
 public:
  ~TempDirs() {
    const char* keep = std::getenv("PLX_KEEP_TEST_DIRS");
    if (getpid() != owner_ || (keep != nullptr && std::string(keep) == "1")) return;
    std::lock_guard<std::mutex> lock(mutex_);
    for (const std::filesystem::path& dir : dirs_) {
      std::error_code ignored;  // a test may have removed it itself
      std::filesystem::remove_all(dir, ignored);
    }
  }
  void Add(std::filesystem::path dir) {
    std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(std::move(dir));
  }

 private:
  const pid_t owner_ = getpid();
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
};

TempDirs& MadeTempDirs() {
  static TempDirs dirs;  // destroyed at exit
  return dirs;
}

}  // namespace

std::string MakeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() /
                       (prefix + "_" + std::to_string(getpid()) + "_" +
                        std::to_string(counter.fetch_add(1)));
  fs::remove_all(dir);
  fs::create_directories(dir);
  MadeTempDirs().Add(dir);
  return dir.string();
}

int64_t ResidentBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atoll(line.c_str() + 6) * 1024;  // in kB
  }
  return -1;
}

}  // namespace plx::testing

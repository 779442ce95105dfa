#include "tests/test_util.h"

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

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

std::string MakeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() /
                       (prefix + "_" + std::to_string(getpid()) + "_" +
                        std::to_string(counter.fetch_add(1)));
  fs::remove_all(dir);
  fs::create_directories(dir);
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

// Shared by the libFuzzer harnesses in fuzz/: a scratch folder for the readers that take a path,
// and the check that turns a broken promise of the code under test into a crash libFuzzer keeps.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <sanitizer/common_interface_defs.h>

namespace plx::fuzz {

// Aborts with `what` when `condition` is false. The harnesses check what the functions promise
// (a parsed header has a positive size, a file that loads saves and loads again, ...) as well as
// the sanitizers' memory and UB checks; abort() is a crash libFuzzer saves a reproducer for.
// The message also goes through the sanitizers' report channel: scripts/fuzz.sh closes the
// harnesses' stderr (-close_fd_mask=2, libpng prints a line per corrupt image), which that
// channel survives.
#define PLX_FUZZ_CHECK(condition, what)                                                \
  do {                                                                                 \
    if (!(condition)) {                                                                \
      ::plx::fuzz::CheckFailed(__FILE__, __LINE__, #condition, std::string(what));     \
    }                                                                                  \
  } while (false)

[[noreturn]] inline void CheckFailed(const char* file, int line, const char* condition,
                                     const std::string& what) {
  char message[1024];
  std::snprintf(message, sizeof(message), "%s:%d: PLX_FUZZ_CHECK(%s) failed: %s", file, line,
                condition, what.c_str());
  std::fprintf(stderr, "%s\n", message);
  __sanitizer_report_error_summary(message);
  std::abort();
}

// A folder of this process's own under $TMPDIR (scripts/fuzz.sh points TMPDIR into
// build-fuzz/tmp and removes it afterwards, so a crashed run leaves nothing elsewhere). Several
// fuzzers, or -jobs, may run at once: the folder name carries the pid via mkdtemp.
inline const std::string& ScratchDir() {
  static const std::string dir = [] {
    std::string pattern = (std::filesystem::temp_directory_path() / "plx_fuzz_XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) CheckFailed(__FILE__, __LINE__, "mkdtemp", pattern);
    return pattern;
  }();
  return dir;
}

inline std::string ScratchPath(const std::string& name) {
  return (std::filesystem::path(ScratchDir()) / name).string();
}

// Writes `bytes` to `path`, replacing it; aborts when it cannot (the harness, not the input, is
// broken then).
inline void WriteFileOrDie(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) CheckFailed(__FILE__, __LINE__, "write", "cannot write " + path);
}

}  // namespace plx::fuzz

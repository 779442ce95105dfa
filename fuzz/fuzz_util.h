// Shared by the libFuzzer harnesses in fuzz/: a scratch folder for the readers that take a path,
// and the check that turns a broken promise of the code under test into a crash libFuzzer keeps.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace plx::fuzz {

// Aborts with `what` when `condition` is false. The harnesses check what the functions promise
// (a parsed header has a positive size, a file that loads saves and loads again, ...) as well as
// the sanitizers' memory and UB checks; abort() is a crash libFuzzer saves a reproducer for.
#define PLX_FUZZ_CHECK(condition, what)                                               \
  do {                                                                                \
    if (!(condition)) {                                                               \
      std::fprintf(stderr, "%s:%d: PLX_FUZZ_CHECK(%s) failed: %s\n", __FILE__, __LINE__, \
                   #condition, std::string(what).c_str());                            \
      std::abort();                                                                   \
    }                                                                                 \
  } while (false)

// A folder of this process's own under $TMPDIR (scripts/fuzz.sh points TMPDIR into
// build-fuzz/tmp and removes it afterwards, so a crashed run leaves nothing elsewhere). Several
// fuzzers, or -jobs, may run at once: the folder name carries the pid via mkdtemp.
inline const std::string& ScratchDir() {
  static const std::string dir = [] {
    std::string pattern = (std::filesystem::temp_directory_path() / "plx_fuzz_XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) {
      std::perror("mkdtemp");
      std::abort();
    }
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
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    std::abort();
  }
}

}  // namespace plx::fuzz

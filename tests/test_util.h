// Shared test helpers: where the dev datasets live, and scratch directories.
#pragma once

#include <cstdint>
#include <string>

namespace plx::testing {

// Folder holding ../shared/data (tum_fr3_teddy, replica_room0), from $PLX_DATA_DIR or the build
// configuration; empty when it does not exist.
std::string SharedDataDir();

// Path of one dev sequence, or empty when the data is absent. Tests call GTEST_SKIP on empty.
std::string SharedSequence(const std::string& name);

// A fresh, empty directory under the system temp dir, unique per call; removed with what is in
// it when the test binary exits (PLX_KEEP_TEST_DIRS=1 keeps it).
std::string MakeTempDir(const std::string& prefix);

// This process's resident memory in bytes (VmRSS of /proc/self/status), -1 when unreadable: what
// a test of an in-process server reads to bound the memory a request costs.
int64_t ResidentBytes();

}  // namespace plx::testing

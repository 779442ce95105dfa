// Shared test helpers: where the dev datasets live, and scratch directories.
#pragma once

#include <string>

namespace plx::testing {

// Folder holding ../shared/data (tum_fr3_teddy, replica_room0), from $PLX_DATA_DIR or the build
// configuration; empty when it does not exist.
std::string SharedDataDir();

// Path of one dev sequence, or empty when the data is absent. Tests call GTEST_SKIP on empty.
std::string SharedSequence(const std::string& name);

// A fresh, empty directory under the system temp dir, unique per call.
std::string MakeTempDir(const std::string& prefix);

}  // namespace plx::testing

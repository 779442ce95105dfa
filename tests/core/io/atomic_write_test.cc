#include "core/io/atomic_write.h"

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "tests/test_util.h"

namespace plx {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

std::string ReadFileToString(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

int EntriesIn(const std::string& dir) {
  int n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

TEST(AtomicWriteTest, WritesEveryFileAndLeavesNoTemporary) {
  const std::string dir = testing::MakeTempDir("plx_atomic");
  const std::string a = dir + "/a.png", b = dir + "/b.txt";
  ASSERT_TRUE(WriteFilesAtomically({{a, "first"}, {b, std::string("x\0y", 3)}}, "test").ok());
  EXPECT_EQ(ReadFileToString(a), "first");
  EXPECT_EQ(ReadFileToString(b), std::string("x\0y", 3));
  EXPECT_EQ(EntriesIn(dir), 2);
  // Replacing an existing file.
  ASSERT_TRUE(WriteFileAtomically(a, "second", "test").ok());
  EXPECT_EQ(ReadFileToString(a), "second");
  EXPECT_EQ(EntriesIn(dir), 2);
}

TEST(AtomicWriteTest, AMissingDirectoryWritesNothingAndNamesIt) {
  const std::string dir = testing::MakeTempDir("plx_atomic");
  const std::string a = dir + "/a.png";
  const absl::Status s =
      WriteFilesAtomically({{a, "data"}, {dir + "/no/such/b.png", "data"}}, "render");
  EXPECT_EQ(s.code(), absl::StatusCode::kNotFound) << s;
  EXPECT_THAT(s.message(), HasSubstr("render"));
  EXPECT_THAT(s.message(), HasSubstr("no/such"));
  EXPECT_EQ(EntriesIn(dir), 0) << "neither the first file nor a temporary was written";
}


// A pid that no process has any more: a child that has exited and been reaped.
int64_t DeadPid() {
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(0);
  ::waitpid(pid, nullptr, 0);
  return pid;
}

TEST(AtomicWriteTest, StaleTemporariesOfDeadWritersAreRemovedAndOthersKept) {
  const std::string dir = testing::MakeTempDir("plx_atomic_stale");
  const int64_t dead = DeadPid();
  const std::string mine = std::to_string(::getpid());
  const std::vector<std::string> stale = {absl::StrCat("room.plx.tmp.", dead),
                                          absl::StrCat("b.plx.tmp.", dead, ".plx")};
  const std::vector<std::string> kept = {
      "room.plx", "room.plx.tmp." + mine,                  // a map; a save of ours in progress
      absl::StrCat("notes.txt.tmp.", dead),               // not a map's temporary
      absl::StrCat("c.plx.tmp.", dead, "x"),              // not a name TempPath makes
      absl::StrCat("c.plx.tmp.", dead, ".png")};
  for (const std::string& name : stale) std::ofstream(dir + "/" + name) << "partial";
  for (const std::string& name : kept) std::ofstream(dir + "/" + name) << "keep";
  // A link is not a temporary of ours, whatever its name.
  fs::create_symlink(dir + "/room.plx", absl::StrCat(dir, "/link.plx.tmp.", dead));

  const std::vector<StaleTempFile> removed = RemoveStaleTempFiles(dir, ".plx");
  std::vector<std::string> names;
  for (const StaleTempFile& f : removed) {
    EXPECT_TRUE(f.removed.ok()) << f.removed;
    EXPECT_EQ(f.pid, dead);
    names.push_back(fs::path(f.path).filename().string());
  }
  EXPECT_THAT(names, ::testing::UnorderedElementsAreArray(stale));
  for (const std::string& name : stale) EXPECT_FALSE(fs::exists(dir + "/" + name)) << name;
  for (const std::string& name : kept) EXPECT_TRUE(fs::exists(dir + "/" + name)) << name;
  EXPECT_TRUE(fs::is_symlink(absl::StrCat(dir, "/link.plx.tmp.", dead)));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace plx

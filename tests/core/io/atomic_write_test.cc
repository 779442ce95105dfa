#include "core/io/atomic_write.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace plx

// Log lines (server/log.h): values from clients can neither break a line nor put control bytes
// on an operator's terminal, and a huge name does not make a huge line.
#include "server/log.h"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx::server {
namespace {

using ::testing::EndsWith;
using ::testing::HasSubstr;

std::string Logged(const std::string& event, std::vector<LogField> fields) {
  ::testing::internal::CaptureStderr();
  LogEvent("info", event, fields);
  return ::testing::internal::GetCapturedStderr();
}

// Only printable ASCII, and the one newline at the end ("…" aside, which marks a cut).
void ExpectOneCleanLine(const std::string& line) {
  ASSERT_FALSE(line.empty());
  EXPECT_EQ(line.find('\n'), line.size() - 1) << line;
  std::string body = line.substr(0, line.size() - 1);
  for (size_t at; (at = body.find("…")) != std::string::npos;) body.erase(at, 3);
  for (const char c : body) {
    EXPECT_TRUE(c >= 0x20 && c < 0x7F) << "byte " << static_cast<int>(static_cast<unsigned char>(c))
                                       << " in " << line;
  }
}

TEST(LogTest, ControlCharactersAndNulAreEscaped) {
  const std::string line = Logged(
      "rpc", {{"map", std::string("a\x01" "b\0c\x1b[2J\x7f\xff", 11)},
              {"message", "two\nlines\tand \"quotes\" \\"}});
  ExpectOneCleanLine(line);
  EXPECT_THAT(line, HasSubstr(R"(map="a\x01b\x00c\x1b[2J\x7f\xff")"));
  EXPECT_THAT(line, HasSubstr(R"(message="two\nlines\tand \"quotes\" \\")"));
}

TEST(LogTest, PlainValuesStayUnquotedAndEmptyOnesAreQuoted) {
  const std::string line = Logged("rpc", {{"map", "room_1.v2"}, {"job", ""}, {"code", "a=b"}});
  EXPECT_THAT(line, HasSubstr(" map=room_1.v2 job=\"\" code=\"a=b\""));
}

TEST(LogTest, NamesAreCappedAt128AndTextAt1024Characters) {
  const std::string name(300 * 1000, 'n');
  const std::string line = Logged("rpc", {{"map", name}, {"message", std::string(600, 'm')}});
  ExpectOneCleanLine(line);
  EXPECT_THAT(line, HasSubstr(" map=" + std::string(kMaxLogNameChars, 'n') + "… "));
  EXPECT_THAT(line, EndsWith(" message=" + std::string(600, 'm') + "\n"));
  EXPECT_LT(line.size(), 1000u);

  const std::string long_text = Logged("rpc", {{"error", std::string(5000, 'e')}});
  EXPECT_THAT(long_text, EndsWith(" error=" + std::string(kMaxLogTextChars, 'e') + "…\n"));
  // The cap counts escaped characters and never splits an escape.
  const std::string controls = Logged("rpc", {{"map", std::string(100, '\x01')}});
  ExpectOneCleanLine(controls);
  std::string expected;
  for (size_t i = 0; i < kMaxLogNameChars / 4; ++i) expected += "\\x01";
  EXPECT_THAT(controls, EndsWith(" map=\"" + expected + "…\"\n"));
}

}  // namespace
}  // namespace plx::server

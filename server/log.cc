#include "server/log.h"

#include <cstdio>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"

namespace plx::server {
namespace {

bool IsTextKey(absl::string_view key) {
  return key == "message" || key == "error" || key == "reason" || key == "devices" ||
         key == "file";
}

// One logfmt value. Values carry client input (map names, job ids, messages quoting them), so a
// value can neither break the line nor smuggle terminal control sequences into it: printable
// ASCII stays, '"' and '\' are escaped, newline and tab become \n and \t, every other byte
// (NUL, controls, DEL, non-ASCII) becomes \xNN. At most `max_chars` characters are written,
// then "…" marks the cut.
std::string Value(absl::string_view value, size_t max_chars) {
  std::string out;
  bool quote = value.empty();
  bool cut = false;
  for (const char ch : value) {
    const unsigned char c = static_cast<unsigned char>(ch);
    std::string piece;
    if (c == '"' || c == '\\') {
      piece = {'\\', ch};
    } else if (c == '\n') {
      piece = "\\n";
    } else if (c == '\t') {
      piece = "\\t";
    } else if (c < 0x20 || c >= 0x7F) {
      piece = absl::StrFormat("\\x%02x", c);
    } else {
      piece.assign(1, ch);
    }
    if (out.size() + piece.size() > max_chars) {
      cut = true;
      break;
    }
    quote = quote || c == ' ' || c == '=' || piece.size() > 1;
    out += piece;
  }
  if (cut) out += "…";
  return quote ? absl::StrCat("\"", out, "\"") : out;
}

}  // namespace

void LogEvent(const char* level, const std::string& event,
              absl::Span<const LogField> fields) {
  std::string line = absl::StrCat(
      "ts=", absl::FormatTime("%Y-%m-%dT%H:%M:%E3SZ", absl::Now(), absl::UTCTimeZone()),
      " level=", level, " event=", Value(event, kMaxLogNameChars));
  for (const auto& [key, value] : fields) {
    absl::StrAppend(&line, " ", key, "=",
                    Value(value, IsTextKey(key) ? kMaxLogTextChars : kMaxLogNameChars));
  }
  line += "\n";
  static std::mutex mutex;
  std::lock_guard<std::mutex> lock(mutex);
  std::fputs(line.c_str(), stderr);
}

}  // namespace plx::server

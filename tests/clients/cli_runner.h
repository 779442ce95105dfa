// Helpers for tests that drive the real `plenox` executable: run it as a subprocess with
// separate stdout/stderr capture, an exit code and a timeout; snapshot a folder to prove a
// failing command wrote nothing; and read the flat JSON objects the CLI prints.
//
// Header-only on purpose: tests/CMakeLists.txt globs only *_test.cc into plx_client_tests.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/test_util.h"

namespace plx::testing {

#ifdef PLENOX_BINARY
inline constexpr char kPlenoxBinary[] = PLENOX_BINARY;
#endif

struct CommandResult {
  int exit_code = -1;      // the process's exit status; 128 + signal when it was killed
  bool signaled = false;   // ended by a signal (a crash, or our timeout kill)
  bool timed_out = false;  // we killed it at the deadline
  bool spawn_failed = false;
  std::string out;  // everything written to stdout
  std::string err;  // everything written to stderr
  double seconds = 0.0;
  std::string command_line;  // for failure messages

  // One block that says what ran and what came back, for EXPECT_* messages: a bare exit code
  // is useless when a CLI test fails.
  std::string Describe() const {
    std::ostringstream s;
    s << "$ " << command_line << "\n-> exit " << exit_code << (signaled ? " (signal)" : "")
      << (timed_out ? " (timed out)" : "") << (spawn_failed ? " (could not start)" : "")
      << " after " << seconds << " s\n--- stdout ---\n"
      << out << "--- stderr ---\n"
      << err << "--------------";
    return s.str();
  }
};

// Runs `binary args...` with `cwd` as its working directory (empty: ours), stdin from
// /dev/null, and kills it after `timeout_s` seconds. Both pipes are drained with poll() so a
// chatty child can never block on a full pipe while we wait for the other one.
inline CommandResult RunCommand(const std::string& binary, const std::vector<std::string>& args,
                                const std::string& cwd = "", double timeout_s = 60.0) {
  CommandResult result;
  result.command_line = binary;
  for (const std::string& a : args) result.command_line += " '" + a + "'";
  const auto start = std::chrono::steady_clock::now();

  // argv and the other strings the child needs are built before fork(): between fork and exec
  // the child of a multithreaded process may only make async-signal-safe calls.
  std::vector<std::string> storage;
  storage.push_back(binary);
  storage.insert(storage.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : storage) argv.push_back(s.data());
  argv.push_back(nullptr);

  int out_pipe[2], err_pipe[2];
  if (::pipe2(out_pipe, O_CLOEXEC) != 0) {
    result.spawn_failed = true;
    return result;
  }
  if (::pipe2(err_pipe, O_CLOEXEC) != 0) {
    ::close(out_pipe[0]);
    ::close(out_pipe[1]);
    result.spawn_failed = true;
    return result;
  }
  const pid_t pid = ::fork();
  if (pid < 0) {
    for (int fd : {out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]}) ::close(fd);
    result.spawn_failed = true;
    return result;
  }
  if (pid == 0) {
    // Its own process group, so the timeout can kill whatever it started as well (a child
    // still holding the pipes would keep us reading forever).
    ::setpgid(0, 0);
    if (!cwd.empty() && ::chdir(cwd.c_str()) != 0) ::_exit(127);
    const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    if (null_fd < 0 || ::dup2(null_fd, 0) < 0 || ::dup2(out_pipe[1], 1) < 0 ||
        ::dup2(err_pipe[1], 2) < 0) {
      ::_exit(127);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  // Also from this side, so the group exists even if we must kill it before the child ran.
  ::setpgid(pid, pid);
  ::close(out_pipe[1]);
  ::close(err_pipe[1]);

  const auto deadline = start + std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000.0));
  struct pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* sinks[2] = {&result.out, &result.err};
  int open_fds = 2;
  char buffer[65536];
  // After the kill, what is still in the pipes is read for at most this long.
  const auto drain_grace = std::chrono::seconds(2);
  while (open_fds > 0) {
    const auto now = std::chrono::steady_clock::now();
    if (!result.timed_out && now >= deadline) {
      // Killing the group closes its pipe ends, so the loop then drains and ends.
      ::kill(-pid, SIGKILL);
      ::kill(pid, SIGKILL);  // in case setpgid failed
      result.timed_out = true;
    }
    const auto until = result.timed_out ? deadline + drain_grace : deadline;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - now);
    if (result.timed_out && left.count() <= 0) break;
    const int ready = ::poll(fds, 2, static_cast<int>(std::max<int64_t>(left.count(), 0)));
    if (ready < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || fds[i].revents == 0) continue;
      const ssize_t n = ::read(fds[i].fd, buffer, sizeof(buffer));
      if (n > 0) {
        sinks[i]->append(buffer, static_cast<size_t>(n));
      } else if (n == 0 || (errno != EINTR && errno != EAGAIN)) {
        ::close(fds[i].fd);
        fds[i].fd = -1;  // poll() ignores negative descriptors
        --open_fds;
      }
    }
  }
  for (const pollfd& p : fds) {
    if (p.fd >= 0) ::close(p.fd);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status)) {
    result.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    result.signaled = true;
    result.exit_code = 128 + WTERMSIG(status);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

#ifdef PLENOX_BINARY
inline CommandResult RunPlenox(const std::vector<std::string>& args, const std::string& cwd = "",
                               double timeout_s = 60.0) {
  return RunCommand(kPlenoxBinary, args, cwd, timeout_s);
}
#endif

// Every path under `dir` (relative, folders included), to compare before and after a command
// that must not write anything.
inline std::set<std::string> ListTree(const std::string& dir) {
  namespace fs = std::filesystem;
  std::set<std::string> paths;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    paths.insert(fs::relative(it->path(), dir).string());
  }
  return paths;
}

inline std::string ReadFileToString(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void WriteStringToFile(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// The last non-empty line of `text` (the CLI's --json output goes there).
inline std::string LastLine(const std::string& text) {
  const size_t end = text.find_last_not_of("\r\n");
  if (end == std::string::npos) return "";
  const size_t newline = text.rfind('\n', end);
  const size_t begin = newline == std::string::npos ? 0 : newline + 1;
  return text.substr(begin, end + 1 - begin);
}

// One value of a flat JSON object: strings unescaped, anything else (numbers, null, true,
// false) kept as its raw text.
struct JsonValue {
  bool is_string = false;
  std::string text;
};
using FlatJson = std::map<std::string, JsonValue>;

// Parses a flat object such as {"a": 1.5, "b": "x", "c": null}: the only JSON the CLI prints.
// Nested objects and arrays are not needed and are rejected, as is anything malformed or any
// repeated key, so that a broken writer fails the test rather than being read leniently.
inline std::optional<FlatJson> ParseFlatJson(const std::string& text) {
  size_t i = 0;
  const auto skip_space = [&] {
    while (i < text.size() &&
           (text[i] == ' ' || text[i] == '\t' || text[i] == '\r' || text[i] == '\n')) {
      ++i;
    }
  };
  const auto parse_string = [&](std::string* out) -> bool {
    if (i >= text.size() || text[i] != '"') return false;
    for (++i; i < text.size(); ++i) {
      const char c = text[i];
      if (c == '"') {
        ++i;
        return true;
      }
      if (static_cast<unsigned char>(c) < 0x20) return false;
      if (c != '\\') {
        out->push_back(c);
        continue;
      }
      if (++i >= text.size()) return false;
      switch (text[i]) {
        case '"': out->push_back('"'); break;
        case '\\': out->push_back('\\'); break;
        case '/': out->push_back('/'); break;
        case 'n': out->push_back('\n'); break;
        case 't': out->push_back('\t'); break;
        case 'r': out->push_back('\r'); break;
        case 'b': out->push_back('\b'); break;
        case 'f': out->push_back('\f'); break;
        case 'u': {
          // Only what the CLI emits: control characters, \u00XX.
          if (i + 4 >= text.size()) return false;
          const std::string hex = text.substr(i + 1, 4);
          if (hex.find_first_not_of("0123456789abcdefABCDEF") != std::string::npos) return false;
          const long code = std::stol(hex, nullptr, 16);
          if (code > 0x7f) return false;
          out->push_back(static_cast<char>(code));
          i += 4;
          break;
        }
        default: return false;
      }
    }
    return false;  // unterminated
  };

  FlatJson object;
  skip_space();
  if (i >= text.size() || text[i] != '{') return std::nullopt;
  ++i;
  skip_space();
  if (i < text.size() && text[i] == '}') {
    ++i;
  } else {
    while (true) {
      skip_space();
      std::string key;
      if (!parse_string(&key)) return std::nullopt;
      skip_space();
      if (i >= text.size() || text[i] != ':') return std::nullopt;
      ++i;
      skip_space();
      JsonValue value;
      if (i < text.size() && text[i] == '"') {
        value.is_string = true;
        if (!parse_string(&value.text)) return std::nullopt;
      } else {
        const size_t end = text.find_first_of(",} \t\r\n", i);
        if (end == std::string::npos || end == i) return std::nullopt;
        value.text = text.substr(i, end - i);
        if (value.text.find_first_of("{[\"") != std::string::npos) return std::nullopt;
        i = end;
      }
      if (!object.emplace(std::move(key), std::move(value)).second) return std::nullopt;
      skip_space();
      if (i < text.size() && text[i] == ',') {
        ++i;
        continue;
      }
      if (i < text.size() && text[i] == '}') {
        ++i;
        break;
      }
      return std::nullopt;
    }
  }
  skip_space();
  if (i != text.size()) return std::nullopt;
  return object;
}

// The number stored under `key`; nullopt when the key is missing, holds a string, or is not a
// complete finite number (the CLI writes null for NaN and infinity).
inline std::optional<double> JsonNumber(const FlatJson& json, const std::string& key) {
  const auto it = json.find(key);
  if (it == json.end() || it->second.is_string) return std::nullopt;
  const std::string& t = it->second.text;
  if (t.empty() || t.find_first_not_of("0123456789+-.eE") != std::string::npos) {
    return std::nullopt;
  }
  size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(t, &used);
  } catch (...) {
    return std::nullopt;
  }
  if (used != t.size()) return std::nullopt;
  return v;
}

// Whitespace-separated fields of the non-comment, non-blank lines of a text file.
inline std::vector<std::vector<std::string>> ReadRows(const std::string& path) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(ReadFileToString(path));
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::vector<std::string> row;
    for (std::string f; fields >> f;) row.push_back(f);
    if (!row.empty() && row[0][0] != '#') rows.push_back(std::move(row));
  }
  return rows;
}

// fields[first, first + count) joined by single spaces.
inline std::string JoinFields(const std::vector<std::string>& fields, size_t first, size_t count) {
  std::string out;
  for (size_t i = first; i < first + count && i < fields.size(); ++i) {
    if (!out.empty()) out += ' ';
    out += fields[i];
  }
  return out;
}

// The JSON object on the last line of stdout, or a failure naming what came back.
inline FlatJson LastLineJson(const CommandResult& r) {
  const std::optional<FlatJson> json = ParseFlatJson(LastLine(r.out));
  EXPECT_TRUE(json.has_value()) << "last stdout line is not a flat JSON object\n" << r.Describe();
  return json.value_or(FlatJson{});
}


// A MakeTempDir folder that is removed when the test passes and kept (for a post-mortem) when
// it fails.
class ScopedTempDir {
 public:
  explicit ScopedTempDir(const std::string& prefix) : path_(MakeTempDir(prefix)) {}
  ~ScopedTempDir() {
    if (!::testing::Test::HasFailure()) {
      std::error_code ec;
      std::filesystem::remove_all(path_, ec);
    }
  }
  ScopedTempDir(const ScopedTempDir&) = delete;
  ScopedTempDir& operator=(const ScopedTempDir&) = delete;

  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

}  // namespace plx::testing

// plenoxd as a subprocess, for what an in-process Daemon cannot show: that the program starts
// and listens, and how (and how fast) it exits on SIGTERM. --listen 127.0.0.1:0; stdout and
// stderr go to files in the test's directory and the port comes from the "plenoxd listening on
// port N" line. Every wait is bounded; a process still running at the end is killed.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"

extern char** environ;

namespace plx::server::testing {

#ifdef PLENOXD_BINARY
inline constexpr char kPlenoxdBinary[] = PLENOXD_BINARY;
#endif

inline double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

inline std::string ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// "metrics on port N" from the stdout (LOG_DIR/plenoxd.out) of a daemon started with
// --metrics-port; -1 when absent.
inline int MetricsPort(const std::string& log_dir) {
  const std::string out = ReadWholeFile(log_dir + "/plenoxd.out");
  const std::string marker = "metrics on port ";
  const size_t at = out.find(marker);
  int port = -1;
  if (at == std::string::npos) return -1;
  const size_t end = out.find_first_not_of("0123456789", at + marker.size());
  return absl::SimpleAtoi(out.substr(at + marker.size(), end - at - marker.size()), &port)
             ? port
             : -1;
}

class DaemonProcess {
 public:
  // Starts `binary` with `flags` after the listen address; `env` ("NAME=value") is added to
  // this process's environment. Logs go to `dir`/plenoxd.out and plenoxd.err.
  DaemonProcess(const std::string& binary, const std::string& dir,
                const std::vector<std::string>& flags, const std::vector<std::string>& env = {})
      : dir_(dir) {
    std::vector<std::string> args = {binary, "--listen", "127.0.0.1:0"};
    args.insert(args.end(), flags.begin(), flags.end());
    std::vector<std::string> environment = env;
    for (char** e = environ; *e != nullptr; ++e) environment.emplace_back(*e);
    // Everything the child needs is built before fork(): between fork and exec a child of a
    // multithreaded process may only make async-signal-safe calls.
    std::vector<char*> argv, envp;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    for (std::string& e : environment) envp.push_back(e.data());
    envp.push_back(nullptr);
    const std::string out_path = dir + "/plenoxd.out", err_path = dir + "/plenoxd.err";
    pid_ = ::fork();
    if (pid_ == 0) {
      ::setpgid(0, 0);  // keeps a terminal's Ctrl-C for the test runner away from it
      const int in = ::open("/dev/null", O_RDONLY);
      const int out = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int err = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (in < 0 || out < 0 || err < 0 || ::dup2(in, 0) < 0 || ::dup2(out, 1) < 0 ||
          ::dup2(err, 2) < 0) {
        ::_exit(127);
      }
      ::execve(argv[0], argv.data(), envp.data());
      ::_exit(127);
    }
  }
  ~DaemonProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  pid_t pid() const { return pid_; }

  // Waits until the daemon says it listens; its port, or -1 when it exited or `timeout` passed.
  int WaitListening(std::chrono::milliseconds timeout = std::chrono::seconds(30)) {
    const std::string marker = "plenoxd listening on port ";
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (pid_ > 0 && std::chrono::steady_clock::now() < deadline) {
      const std::string out = ReadWholeFile(dir_ + "/plenoxd.out");
      const size_t at = out.find(marker);
      if (at != std::string::npos && out.find('\n', at) != std::string::npos) {
        return std::atoi(out.c_str() + at + marker.size());
      }
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {  // it exited instead
        pid_ = -1;
        return -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }

  struct Exit {
    int code = -1;         // exit status; 128 + signal when a signal ended it; -1: killed by us
    double seconds = 0.0;  // from SIGTERM to exit
  };
  // SIGTERM, then waits up to `timeout` for the exit (SIGKILL after that).
  Exit Stop(std::chrono::milliseconds timeout) {
    Exit exit;
    if (pid_ <= 0) return exit;
    const auto start = std::chrono::steady_clock::now();
    ::kill(pid_, SIGTERM);
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() - start > timeout) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        pid_ = -1;
        exit.seconds = SecondsSince(start);
        return exit;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    pid_ = -1;
    exit.seconds = SecondsSince(start);
    if (WIFEXITED(status)) exit.code = WEXITSTATUS(status);
    if (WIFSIGNALED(status)) exit.code = 128 + WTERMSIG(status);
    return exit;
  }

  // SIGKILL (a crash, an OOM kill): no drain, no save. Waits for the process to be gone.
  void Kill() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

  std::string Log() const {
    return "--- plenoxd stdout ---\n" + ReadWholeFile(dir_ + "/plenoxd.out") +
           "--- plenoxd stderr ---\n" + ReadWholeFile(dir_ + "/plenoxd.err");
  }

 private:
  std::string dir_;
  pid_t pid_ = -1;
};

}  // namespace plx::server::testing

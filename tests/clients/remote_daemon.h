// plenoxd for the CLI's black-box tests (remote_cli_test.cc, remote_slam_cli_test.cc): a port
// nothing listens on, the daemon binary as a subprocess on a free port with a scratch data
// directory, and the daemon and synthetic sequence a suite of such tests shares.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/clients/cli_runner.h"
#include "tests/test_util.h"

namespace plx::testing {

// A port nothing listens on: bound and released again (nothing else takes it in the meantime
// on a test machine, and if something did the test would still see no plenoxd there).
inline int UnusedPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;
  socklen_t length = sizeof(address);
  int port = -1;
  if (fd >= 0 && ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) == 0) {
    port = ntohs(address.sin_port);
  }
  if (fd >= 0) ::close(fd);
  return port;
}

#ifdef PLENOXD_BINARY

// plenoxd as a subprocess: --listen 127.0.0.1:0 and a data directory under `dir`; stdout and
// stderr go to files there (no pipe to keep drained), and the port comes from the
// "plenoxd listening on port N" line.
class DaemonProcess {
 public:
  DaemonProcess(const std::string& dir, const std::vector<std::string>& extra_flags)
      : dir_(dir) {
    std::vector<std::string> storage = {PLENOXD_BINARY, "--listen", "127.0.0.1:0", "--data-dir",
                                        dir + "/data", "--threads", "2"};
    storage.insert(storage.end(), extra_flags.begin(), extra_flags.end());
    std::vector<char*> argv;
    for (std::string& s : storage) argv.push_back(s.data());
    argv.push_back(nullptr);
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
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    if (pid_ < 0) return;
    const std::string marker = "plenoxd listening on port ";
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < deadline) {
      const std::string out = ReadFileToString(out_path);
      const size_t at = out.find(marker);
      if (at != std::string::npos && out.find('\n', at) != std::string::npos) {
        port_ = std::atoi(out.c_str() + at + marker.size());
        return;
      }
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {  // it died instead
        pid_ = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
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

  bool running() const { return pid_ > 0 && port_ > 0; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  std::string data_dir() const { return dir_ + "/data"; }
  std::string Log() const {
    return "--- plenoxd stdout ---\n" + ReadFileToString(dir_ + "/plenoxd.out") +
           "--- plenoxd stderr ---\n" + ReadFileToString(dir_ + "/plenoxd.err");
  }

  // SIGTERM (drain, save dirty maps, exit) and the exit code; -1 when it had to be killed after
  // `timeout_s`, 128 + signal when a signal ended it.
  int Stop(double timeout_s = 20.0) {
    if (pid_ <= 0) return -1;
    ::kill(pid_, SIGTERM);
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(int64_t(timeout_s * 1000));
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        pid_ = -1;
        return -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    pid_ = -1;
    if (WIFEXITED(status)) return WEXITSTATUS(status);
    return WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1;
  }

 private:
  std::string dir_;
  pid_t pid_ = -1;
  int port_ = -1;
};

// What a suite of remote tests shares, made in its SetUpTestSuite: a folder, a synthetic
// sequence (`plenox synth`) in it, and a daemon with its data directory there. Deleting it
// stops the daemon with SIGTERM (drain, save, exit 0 is part of the contract: anything else is
// a failure) and removes the folder unless the suite failed.
class RemoteSuite {
 public:
  RemoteSuite(const std::string& prefix, int frames, int width, int height,
              const std::vector<std::string>& daemon_flags)
      : root_(MakeTempDir(prefix)),
        dataset_(root_ + "/sequence"),
        synth_(RunPlenox({"synth", "--out", dataset_, "--frames", std::to_string(frames),
                          "--width", std::to_string(width), "--height",
                          std::to_string(height)})),
        daemon_(root_, daemon_flags) {}
  ~RemoteSuite() {
    const bool was_running = daemon_.running();
    const int stopped = daemon_.Stop();
    if (was_running && stopped != 0) {
      ADD_FAILURE() << "plenoxd exited with " << stopped << " on SIGTERM\n" << daemon_.Log();
    }
    const ::testing::TestSuite* suite = ::testing::UnitTest::GetInstance()->current_test_suite();
    if ((suite == nullptr || !suite->Failed()) && stopped == 0) {
      std::error_code ec;
      std::filesystem::remove_all(root_, ec);
    }
  }
  RemoteSuite(const RemoteSuite&) = delete;
  RemoteSuite& operator=(const RemoteSuite&) = delete;

  // Whether the sequence was written and the daemon listens; else why not.
  ::testing::AssertionResult Ready() const {
    if (synth_.exit_code != 0) return ::testing::AssertionFailure() << synth_.Describe();
    if (!daemon_.running()) return ::testing::AssertionFailure() << daemon_.Log();
    return ::testing::AssertionSuccess();
  }

  // `plenox --server <the daemon> args...`.
  CommandResult Remote(std::vector<std::string> args, const std::string& cwd = "",
                       double timeout_s = 60.0) const {
    args.insert(args.begin(), {"--server", daemon_.address()});
    return RunPlenox(args, cwd, timeout_s);
  }

  const std::string& root() const { return root_; }
  const std::string& dataset() const { return dataset_; }
  const DaemonProcess& daemon() const { return daemon_; }

 private:
  std::string root_;
  std::string dataset_;
  CommandResult synth_;
  DaemonProcess daemon_;
};

#endif  // PLENOXD_BINARY

}  // namespace plx::testing

// A test guard for code that must never block on a FIFO: if the code under test is still stuck
// `patience` after the valve was made (waiting in open() for the FIFO's other end), the valve
// opens that end itself, so the test ends (and fails on released()) instead of hanging.
//
// Header-only, shared by the core and daemon tests.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

namespace plx::testing {

class FifoValve {
 public:
  // kWriter: the code under test reads the FIFO (the valve plays the writer and closes at once,
  // so the reader sees end of file). kReader: the code writes it (the valve reads and discards
  // until destroyed).
  enum class Role { kWriter, kReader };

  FifoValve(std::string fifo, Role role,
            std::chrono::milliseconds patience = std::chrono::seconds(10))
      : fifo_(std::move(fifo)), thread_([this, role, patience] { Run(role, patience); }) {}
  ~FifoValve() {
    done_ = true;
    thread_.join();
  }

  // True when the code under test was still running after `patience` (blocked on the FIFO)
  // and the valve opened the other end.
  bool released() const { return released_; }

 private:
  void Run(Role role, std::chrono::milliseconds patience) {
    const auto deadline = std::chrono::steady_clock::now() + patience;
    while (!done_ && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (done_) return;
    released_ = true;
    int fd = -1;
    while (!done_) {
      if (fd < 0) {
        // Non-blocking: a writer's open fails (ENXIO) while nobody reads, a reader's succeeds.
        fd = ::open(fifo_.c_str(), (role == Role::kWriter ? O_WRONLY : O_RDONLY) | O_NONBLOCK);
        if (fd >= 0 && role == Role::kWriter) {
          ::close(fd);  // the reader sees end of file
          fd = -1;
        }
      } else {
        char buffer[65536];
        (void)!::read(fd, buffer, sizeof(buffer));  // discard what the writer sends
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (fd >= 0) ::close(fd);
  }

  std::string fifo_;
  std::atomic<bool> done_{false};
  std::atomic<bool> released_{false};
  std::thread thread_;
};

}  // namespace plx::testing

// Raw HTTP over loopback TCP for the tests of the side HTTP server (tests/web) and of the
// daemon's metrics and viewer port (tests/server): connections from a chosen loopback address
// (all of 127.0.0.0/8 is this host, so a test can be several clients), a request sent verbatim,
// and the answer parsed.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/time/time.h"

namespace plx::testing {

// A TCP connection from `source` (a 127.x.y.z address) to 127.0.0.1:`port` whose reads give up
// after `timeout`; -1 on failure.
inline int ConnectLoopbackFrom(const char* source, int port,
                               absl::Duration timeout = absl::Seconds(5)) {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in from{};
  from.sin_family = AF_INET;
  if (inet_pton(AF_INET, source, &from.sin_addr) != 1 ||
      bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof(from)) != 0) {
    close(fd);
    return -1;
  }
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const int64_t micros = absl::ToInt64Microseconds(timeout);
  timeval tv{static_cast<time_t>(micros / 1000000), static_cast<suseconds_t>(micros % 1000000)};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    close(fd);
    return -1;
  }
  return fd;
}

// The same from 127.0.0.1.
inline int ConnectLoopback(int port, absl::Duration timeout = absl::Seconds(5)) {
  return ConnectLoopbackFrom("127.0.0.1", port, timeout);
}

// Sends all of `bytes`; false when the connection fails first.
inline bool SendAll(int fd, const std::string& bytes) {
  size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += static_cast<size_t>(n);
  }
  return true;
}

// Reads until the peer closes or a read times out (the socket's SO_RCVTIMEO).
inline std::string ReadUntilClosed(int fd) {
  std::string response;
  char buffer[16384];
  for (;;) {
    const ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) break;
    response.append(buffer, static_cast<size_t>(n));
  }
  return response;
}

// Sends `request` verbatim to 127.0.0.1:`port` and reads until the server closes (or 5 s pass
// without a byte): the whole response, headers and body, or empty on a connection error.
inline std::string HttpExchange(int port, const std::string& request) {
  const int fd = ConnectLoopback(port);
  if (fd < 0) return "";
  std::string response = SendAll(fd, request) ? ReadUntilClosed(fd) : "";
  close(fd);
  return response;
}

// GET `path` over HTTP/1.0 (the server closes after answering).
inline std::string HttpGet(int port, const std::string& path) {
  return HttpExchange(port, absl::StrCat("GET ", path, " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n"));
}

struct HttpAnswer {
  int status = 0;       // 0: no answer
  std::string headers;  // the raw header block (lower-cased), for find()
  std::string body;
};

// Splits a raw answer into status, headers and body.
inline HttpAnswer ParseHttpAnswer(const std::string& raw) {
  HttpAnswer answer;
  const size_t split = raw.find("\r\n\r\n");
  if (raw.rfind("HTTP/1.1 ", 0) != 0 || split == std::string::npos) return answer;
  if (!absl::SimpleAtoi(raw.substr(9, 3), &answer.status)) answer.status = 0;
  answer.headers = absl::AsciiStrToLower(raw.substr(0, split));
  answer.body = raw.substr(split + 4);
  return answer;
}

// GET `path` (already percent-encoded) with extra header lines ("Name: value\r\n" each).
inline HttpAnswer HttpGetAnswer(int port, const std::string& path,
                                const std::string& extra_headers = "") {
  return ParseHttpAnswer(HttpExchange(
      port, absl::StrCat("GET ", path, " HTTP/1.0\r\nHost: 127.0.0.1\r\n", extra_headers, "\r\n")));
}

// Sockets opened by a test, closed when it ends.
struct Sockets {
  std::vector<int> fds;
  Sockets() = default;
  Sockets(const Sockets&) = delete;
  Sockets& operator=(const Sockets&) = delete;
  ~Sockets() {
    for (int fd : fds) close(fd);
  }
};

}  // namespace plx::testing

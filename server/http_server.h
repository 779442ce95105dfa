// plenoxd's side HTTP server (Prometheus /metrics today; a web viewer can add its routes to the
// same server later). cpp-httplib serves it from a fixed thread pool with read, write and
// keep-alive timeouts, so idle or slow connections hold one pool thread for a bounded time and
// never queue a scrape behind them the way a one-connection-at-a-time loop did. httplib stays
// behind this header.
#pragma once

#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/time/time.h"

namespace plx::server {

struct HttpServerOptions {
  std::string host = "127.0.0.1";  // an address or name to bind; 0.0.0.0 for all interfaces
  int port = 0;                    // 0 picks a free port (HttpServer::port)
  // Connections served at once: each open connection holds one thread while it is read,
  // handled, written or kept alive; more wait their turn.
  int threads = 16;
  // Longest wait for the next bytes of a request / to send response bytes.
  absl::Duration read_timeout = absl::Seconds(5);
  absl::Duration write_timeout = absl::Seconds(5);
  // How long a connection may sit idle (before its first request, or between requests) before
  // it is closed and its thread freed; and how many requests one connection may make.
  absl::Duration keep_alive_timeout = absl::Seconds(2);
  int keep_alive_max_requests = 16;
  // Request bodies larger than this get 413 (GET routes need none; httplib would otherwise
  // buffer any body a client declares).
  size_t max_body_bytes = 64 << 10;
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
};

class HttpServer {
 public:
  // GET (and HEAD) handler for one exact path; runs on a pool thread, so it must be
  // thread-safe.
  using Handler = std::function<HttpResponse()>;

  explicit HttpServer(HttpServerOptions options);
  ~HttpServer();  // stops serving and joins the pool (at most about keep_alive_timeout)
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Routes are registered before Start. Any other path gets 404 listing these paths.
  void Get(const std::string& path, Handler handler);

  // Binds (SO_REUSEADDR only: a second server on a busy port fails instead of sharing it) and
  // serves on a thread of its own. UnavailableError naming host:port when it cannot bind.
  absl::Status Start();

  int port() const { return port_; }

 private:
  struct Impl;
  HttpServerOptions options_;
  std::map<std::string, Handler> routes_;
  std::unique_ptr<Impl> impl_;
  int port_ = -1;
};

}  // namespace plx::server

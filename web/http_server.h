// The programs' side HTTP server: plenoxd's Prometheus /metrics and web viewer, and `plenox view`.
//
// The port is reachable by anyone who reaches the host (the page and /metrics need no token), so
// what one client can cost is bounded here, whatever it sends:
//   - One event-loop thread owns every socket (epoll, non-blocking): an idle or trickling
//     connection costs a few KiB and no thread, so it cannot hold up a scrape.
//   - Deadlines, measured by the server, not by the client's pace: a request head must be
//     complete within `request_timeout` of the connection's accept (or of the previous answer's
//     end), whatever it trickles; a connection with no request starts within
//     `keep_alive_timeout` is closed; an answer that makes no progress for `send_timeout` is
//     dropped.
//   - The head is bounded in bytes and in header count (web/http_request.h); no request body is
//     read.
//   - At most `max_connections` open, `max_connections_per_client` from one address; more are
//     answered 503 and closed at once.
//   - Handlers run on `threads` threads with at most `max_queued_requests` waiting; a request
//     beyond that is answered 503 with Retry-After, never queued without bound.
//   - An answer is held once: a cached body (shared_body) is sent from the cache's copy, and a
//     Range header gets at most one part (web/http_request.h: several ranges collapse to the
//     span that covers them), so no request can make an answer larger than its body.
// Handlers see an HttpRequest and return an HttpResponse; sockets stay behind this header.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/time/time.h"
#include "web/http_request.h"

namespace plx::web {

struct HttpServerOptions {
  std::string host = "127.0.0.1";  // an address or name to bind; 0.0.0.0 for all interfaces
  int port = 0;                    // 0 picks a free port (HttpServer::port)
  int threads = 8;                 // handler threads (a render or a mesh holds one for seconds)
  int max_queued_requests = 64;    // requests waiting for a handler thread; more get 503
  // Open connections in all, and from one client address. Both are also kept under half the
  // process's open-file limit.
  int max_connections = 512;
  int max_connections_per_client = 32;
  // The whole request head, from accept (or from the end of the previous answer on the same
  // connection) to its last byte; a client too slow gets 408 and is closed.
  absl::Duration request_timeout = absl::Seconds(5);
  // How long a connection may wait before its request starts (first, or next on keep-alive).
  absl::Duration keep_alive_timeout = absl::Seconds(2);
  // An answer whose bytes the client stops taking for this long is dropped.
  absl::Duration send_timeout = absl::Seconds(5);
  int keep_alive_max_requests = 16;  // requests per connection
  HttpHeadLimits head_limits;
};

// What a handler sees of a GET (or HEAD) request.
struct HttpRequest {
  std::string path;  // percent-decoded, without the query
  // The query's parameters; a name given twice keeps its first value.
  std::map<std::string, std::string> params;
  std::string authorization;  // the Authorization header, empty when absent

  // The parameter's value, or nullptr when absent.
  const std::string* Param(const std::string& name) const {
    const auto it = params.find(name);
    return it == params.end() ? nullptr : &it->second;
  }
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;                                               // bytes: text or binary
  std::vector<std::pair<std::string, std::string>> headers = {};  // extra response headers
  // When set, sent instead of `body` and never copied: an answer kept in a cache (a point
  // cloud, a mesh, three.js) exists once however many clients are being sent it.
  std::shared_ptr<const std::string> shared_body = nullptr;

  const std::string& Body() const { return shared_body ? *shared_body : body; }
};

// A plain-text response with a trailing newline (errors, mostly).
HttpResponse TextResponse(int status, const std::string& text);

// `text`, which must outlive every answer that carries it (a static, or a member of an object
// that outlives the server), as a shared body without a copy.
std::shared_ptr<const std::string> UnownedBody(const std::string& text);

// Counters since Start, for tests and /metrics.
struct HttpServerStats {
  int64_t connections_open = 0;
  int64_t connections_accepted = 0;
  int64_t connections_refused = 0;    // over max_connections or max_connections_per_client
  int64_t requests = 0;               // complete heads handled (any status)
  int64_t requests_refused_busy = 0;  // 503: every handler thread busy and the queue full
  int64_t timeouts = 0;  // closed by request_timeout, keep_alive_timeout or send_timeout
};

class HttpServer {
 public:
  // Handlers run on the handler threads, so they must be thread-safe.
  using Handler = std::function<HttpResponse()>;
  using RequestHandler = std::function<HttpResponse(const HttpRequest&)>;

  explicit HttpServer(HttpServerOptions options);
  // Stops accepting, closes every connection, and waits for the handlers that are running.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Routes are registered before Start; GET (and HEAD) only. An exact path:
  void Get(const std::string& path, Handler handler);
  // Every path that starts with `prefix` (which should end in '/'); the longest matching
  // prefix wins, an exact path beats any prefix. Any other path gets 404 listing the routes.
  void GetPrefix(const std::string& prefix, RequestHandler handler);

  // Binds (SO_REUSEADDR only: a second server on a busy port fails instead of sharing it) and
  // serves on a thread of its own. UnavailableError naming host:port when it cannot bind.
  absl::Status Start();

  int port() const { return port_; }
  HttpServerStats stats() const;

 private:
  struct Impl;
  // The handler for `path`, or null.
  const RequestHandler* Find(const std::string& path) const;

  HttpServerOptions options_;
  std::map<std::string, RequestHandler> exact_;
  std::map<std::string, RequestHandler> prefixes_;
  std::unique_ptr<Impl> impl_;
  int port_ = -1;
};

}  // namespace plx::web

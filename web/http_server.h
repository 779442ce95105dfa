// The programs' side HTTP server: plenoxd's Prometheus /metrics and web viewer, and `plenox view`.
// cpp-httplib serves it from a fixed thread pool with read, write and keep-alive timeouts, so
// idle or slow connections hold one pool thread for a bounded time and never queue a scrape
// behind them the way a one-connection-at-a-time loop did. httplib stays behind this header:
// handlers see an HttpRequest and return an HttpResponse.
#pragma once

#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/time/time.h"

namespace plx::web {

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

// What a handler sees of a GET request. httplib has already bounded the request line and
// headers (8 KiB each, 414/400 beyond) and decoded the query's percent escapes.
struct HttpRequest {
  std::string path;  // without the query
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
  std::string body;  // bytes: text or binary
  std::vector<std::pair<std::string, std::string>> headers = {};  // extra response headers
};

// A plain-text response with a trailing newline (errors, mostly).
HttpResponse TextResponse(int status, const std::string& text);

class HttpServer {
 public:
  // Handlers run on pool threads, so they must be thread-safe.
  using Handler = std::function<HttpResponse()>;
  using RequestHandler = std::function<HttpResponse(const HttpRequest&)>;

  explicit HttpServer(HttpServerOptions options);
  ~HttpServer();  // stops serving and joins the pool (at most about keep_alive_timeout)
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

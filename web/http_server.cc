#include "web/http_server.h"

#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <utility>
#include <vector>

#include <httplib.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace plx::web {
namespace {

// httplib takes seconds and microseconds.
std::pair<time_t, time_t> SecondsAndMicros(absl::Duration d) {
  const int64_t micros = absl::ToInt64Microseconds(d);
  return {static_cast<time_t>(micros / 1000000), static_cast<time_t>(micros % 1000000)};
}

}  // namespace

struct HttpServer::Impl {
  httplib::Server server;
  std::thread thread;
  std::atomic<bool> listen_returned{false};
};

HttpServer::HttpServer(HttpServerOptions options)
    : options_(std::move(options)), impl_(std::make_unique<Impl>()) {}

HttpServer::~HttpServer() {
  if (impl_->thread.joinable()) {
    impl_->server.stop();
    impl_->thread.join();
  }
}

HttpResponse TextResponse(int status, const std::string& text) {
  return HttpResponse{status, "text/plain; charset=utf-8", text + "\n"};
}

void HttpServer::Get(const std::string& path, Handler handler) {
  exact_[path] = [handler = std::move(handler)](const HttpRequest&) { return handler(); };
}

void HttpServer::GetPrefix(const std::string& prefix, RequestHandler handler) {
  prefixes_[prefix] = std::move(handler);
}

const HttpServer::RequestHandler* HttpServer::Find(const std::string& path) const {
  if (const auto exact = exact_.find(path); exact != exact_.end()) return &exact->second;
  const RequestHandler* best = nullptr;
  size_t best_length = 0;
  for (const auto& [prefix, handler] : prefixes_) {
    if (path.size() >= prefix.size() && path.compare(0, prefix.size(), prefix) == 0 &&
        prefix.size() >= best_length) {
      best = &handler;
      best_length = prefix.size();
    }
  }
  return best;
}

absl::Status HttpServer::Start() {
  httplib::Server& s = impl_->server;
  const auto [read_s, read_us] = SecondsAndMicros(options_.read_timeout);
  const auto [write_s, write_us] = SecondsAndMicros(options_.write_timeout);
  s.set_read_timeout(read_s, read_us);
  s.set_write_timeout(write_s, write_us);
  // Whole seconds only in httplib; a sub-second timeout would round to 0 and close every
  // connection before its first request.
  s.set_keep_alive_timeout(
      std::max<time_t>(1, static_cast<time_t>(absl::ToInt64Seconds(options_.keep_alive_timeout))));
  s.set_keep_alive_max_count(static_cast<size_t>(std::max(1, options_.keep_alive_max_requests)));
  s.set_payload_max_length(options_.max_body_bytes);
  const size_t threads = static_cast<size_t>(std::max(1, options_.threads));
  s.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  // httplib's default also sets SO_REUSEPORT, which would let a second daemon bind the same
  // port and take half the scrapes.
  s.set_socket_options([](int fd) {
    const int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  });

  // One catch-all route: paths are matched here (exactly, or by prefix) rather than as
  // httplib's regexes.
  std::vector<std::string> paths;
  for (const auto& [path, handler] : exact_) paths.push_back(path);
  for (const auto& [prefix, handler] : prefixes_) paths.push_back(prefix + "...");
  const std::string not_found = absl::StrCat("plenoxd serves ", absl::StrJoin(paths, ", "), "\n");
  s.Get(".*", [this, not_found](const httplib::Request& request, httplib::Response& response) {
    const RequestHandler* handler = Find(request.path);
    if (handler == nullptr) {
      response.status = 404;
      response.set_content(not_found, "text/plain; charset=utf-8");
      return;
    }
    HttpRequest r;
    r.path = request.path;
    for (const auto& [name, value] : request.params) r.params.emplace(name, value);
    r.authorization = request.get_header_value("Authorization");
    HttpResponse answer = (*handler)(r);
    response.status = answer.status;
    for (const auto& [name, value] : answer.headers) response.set_header(name, value);
    response.set_content(std::move(answer.body), answer.content_type.c_str());
  });

  const bool bound = options_.port == 0 ? (port_ = s.bind_to_any_port(options_.host)) > 0
                                        : s.bind_to_port(options_.host, options_.port);
  if (!bound) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options_.host, ":",
                                               options_.port, " (address in use or not local?)"));
  }
  if (options_.port != 0) port_ = options_.port;
  Impl* impl = impl_.get();
  impl->thread = std::thread([impl] {
    impl->server.listen_after_bind();
    impl->listen_returned = true;
  });
  // stop() is a no-op until the listening loop runs, so the destructor could otherwise miss it.
  while (!s.is_running() && !impl->listen_returned) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (impl->listen_returned) {
    return absl::UnavailableError(absl::StrCat("cannot serve on ", options_.host, ":", port_));
  }
  return absl::OkStatus();
}

}  // namespace plx::web

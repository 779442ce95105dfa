#include "web/http_server.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "web/handler_pool.h"

namespace plx::web {
namespace {

using Clock = std::chrono::steady_clock;

// epoll's user data: the listening socket, the wake-up eventfd, then connection ids.
constexpr uint64_t kListenId = 0;
constexpr uint64_t kWakeId = 1;
// How often deadlines are checked: their resolution, well under a second.
constexpr auto kSweepInterval = std::chrono::milliseconds(50);
// Bytes read from a connection ahead of its head being parsed: a complete head plus a little
// of a pipelined next request; more waits in the kernel until this request is answered.
constexpr size_t kReadChunk = 16384;

Clock::duration ToClock(absl::Duration d) {
  return std::chrono::microseconds(absl::ToInt64Microseconds(d));
}

// An answer ready to send: the head's bytes and the body's part [begin, end).
struct Answer {
  std::string head;
  std::shared_ptr<const std::string> body;  // null when the answer has none (HEAD, errors)
  size_t begin = 0, end = 0;
  bool close = false;
};

// A header a handler set is sent only when it cannot split the head.
bool SafeHeader(const std::string& name, const std::string& value) {
  auto clean = [](const std::string& s) { return s.find_first_of("\r\n") == std::string::npos; };
  return !name.empty() && clean(name) && clean(value) && name.find(':') == std::string::npos;
}

// The answer to a request: the status line, the headers, and at most one part of the body
// (web/http_request.h, ParseByteRange) for a 200 when `range` is set.
Answer MakeAnswer(HttpResponse response, bool head_only, bool keep_alive,
                  const std::string* range) {
  Answer a;
  a.close = !keep_alive;
  a.body = response.shared_body ? std::move(response.shared_body)
                                : std::make_shared<const std::string>(std::move(response.body));
  int status = response.status;
  const uint64_t size = a.body->size();
  a.end = a.body->size();
  std::string extra;
  if (status == 200 && range != nullptr) {
    const ByteRange r = ParseByteRange(*range, size);
    if (r.kind == ByteRange::Kind::kPart) {
      status = 206;
      a.begin = static_cast<size_t>(r.first);
      a.end = static_cast<size_t>(r.last) + 1;
      absl::StrAppend(&extra, "Content-Range: bytes ", r.first, "-", r.last, "/", size, "\r\n");
    } else if (r.kind == ByteRange::Kind::kUnsatisfiable) {
      status = 416;
      a.body = nullptr;
      a.end = 0;
      absl::StrAppend(&extra, "Content-Range: bytes */", size, "\r\n");
    }
  }
  if (status == 200 || status == 206) extra += "Accept-Ranges: bytes\r\n";
  absl::StrAppend(&a.head, "HTTP/1.1 ", status, " ", HttpReasonPhrase(status), "\r\n");
  if (a.body != nullptr) absl::StrAppend(&a.head, "Content-Type: ", response.content_type, "\r\n");
  absl::StrAppend(&a.head, "Content-Length: ", a.end - a.begin, "\r\n", extra);
  for (const auto& [name, value] : response.headers) {
    if (SafeHeader(name, value)) absl::StrAppend(&a.head, name, ": ", value, "\r\n");
  }
  absl::StrAppend(&a.head, "Connection: ", keep_alive ? "keep-alive" : "close", "\r\n\r\n");
  if (head_only) {
    a.body = nullptr;
    a.begin = a.end = 0;
  }
  return a;
}

Answer ErrorAnswer(int status, const std::string& reason, bool head_only, bool keep_alive,
                   std::vector<std::pair<std::string, std::string>> headers = {}) {
  HttpResponse r = TextResponse(status, reason);
  r.headers = std::move(headers);
  return MakeAnswer(std::move(r), head_only, keep_alive, nullptr);
}

// The client's address without its port: the key of the per-client connection limit.
std::string ClientAddress(const sockaddr_storage& addr) {
  char text[INET6_ADDRSTRLEN] = {0};
  if (addr.ss_family == AF_INET) {
    const auto* v4 = reinterpret_cast<const sockaddr_in*>(&addr);
    inet_ntop(AF_INET, &v4->sin_addr, text, sizeof(text));
  } else if (addr.ss_family == AF_INET6) {
    const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&addr);
    inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof(text));
  }
  return text;
}

// Reads what a client already sent (so that closing does not reset the connection under the
// answer before the client reads it), then closes.
void DrainAndClose(int fd) {
  shutdown(fd, SHUT_WR);
  char sink[4096];
  for (int i = 0; i < 16 && recv(fd, sink, sizeof(sink), MSG_DONTWAIT) > 0; ++i) {
  }
  close(fd);
}

}  // namespace

HttpResponse TextResponse(int status, const std::string& text) {
  return HttpResponse{status, "text/plain; charset=utf-8", text + "\n"};
}

std::shared_ptr<const std::string> UnownedBody(const std::string& text) {
  // The aliasing constructor: points at `text`, owns nothing.
  return std::shared_ptr<const std::string>(std::shared_ptr<const void>(), &text);
}

struct HttpServer::Impl {
  enum class Phase { kReading, kHandling, kSending };
  struct Connection {
    int fd = -1;
    std::string client;
    Phase phase = Phase::kReading;
    Clock::time_point phase_start;    // accept, or the end of the previous answer
    Clock::time_point last_progress;  // sending: the last time bytes went out
    std::string in;
    Answer out;
    size_t sent = 0;  // of out.head, then of the body's part
    int requests = 0;
    uint32_t events = 0;
  };

  Impl(HttpServer* owner, const HttpServerOptions& options) : owner(owner), options(options) {}
  ~Impl();

  void Loop();
  void Accept();
  void OnReadable(uint64_t id, Connection& c);
  void Parse(uint64_t id, Connection& c);
  void Dispatch(uint64_t id, Connection& c, const HttpRequestHead& head);
  void StartSending(uint64_t id, Connection& c, Answer answer);
  void OnWritable(uint64_t id, Connection& c);
  void Close(uint64_t id);
  void SetEvents(uint64_t id, Connection& c, uint32_t events);
  void TakeFinished();
  void Sweep(Clock::time_point now);
  // From a handler thread: `answer` is ready for connection `id` (which may be gone by then).
  void Finished(uint64_t id, Answer answer);

  HttpServer* const owner;
  const HttpServerOptions options;
  int max_connections = 0;
  std::string not_found;
  int listen_fd = -1, epoll_fd = -1, wake_fd = -1;
  std::thread thread;
  std::atomic<bool> stopping{false};
  std::unique_ptr<HandlerPool> pool;

  // The loop thread's own.
  std::unordered_map<uint64_t, Connection> connections;
  std::unordered_map<std::string, int> per_client;
  uint64_t next_id = 2;
  bool accept_paused = false;  // out of file descriptors: resumed at the next sweep

  std::mutex finished_mutex;
  std::vector<std::pair<uint64_t, Answer>> finished;

  std::atomic<int64_t> open{0}, accepted{0}, refused{0}, requests{0}, busy{0}, timeouts{0};
};

HttpServer::Impl::~Impl() {
  if (thread.joinable()) {
    stopping = true;
    const uint64_t one = 1;
    (void)!write(wake_fd, &one, sizeof(one));
    thread.join();
  }
  pool.reset();  // running handlers finish; their answers go nowhere
  for (auto& [id, c] : connections) close(c.fd);
  for (const int fd : {listen_fd, epoll_fd, wake_fd}) {
    if (fd >= 0) close(fd);
  }
}

void HttpServer::Impl::SetEvents(uint64_t id, Connection& c, uint32_t events) {
  if (c.events == events) return;
  epoll_event ev{};
  ev.events = events;
  ev.data.u64 = id;
  epoll_ctl(epoll_fd, EPOLL_CTL_MOD, c.fd, &ev);
  c.events = events;
}

void HttpServer::Impl::Close(uint64_t id) {
  const auto it = connections.find(id);
  if (it == connections.end()) return;
  epoll_ctl(epoll_fd, EPOLL_CTL_DEL, it->second.fd, nullptr);
  DrainAndClose(it->second.fd);
  if (--per_client[it->second.client] <= 0) per_client.erase(it->second.client);
  connections.erase(it);
  --open;
}

void HttpServer::Impl::Accept() {
  for (;;) {
    sockaddr_storage addr{};
    socklen_t len = sizeof(addr);
    const int fd =
        accept4(listen_fd, reinterpret_cast<sockaddr*>(&addr), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
        // The pending connection would make the listening socket readable for ever: stop
        // watching it until the next sweep instead of spinning.
        epoll_event ev{};
        ev.data.u64 = kListenId;
        epoll_ctl(epoll_fd, EPOLL_CTL_MOD, listen_fd, &ev);
        accept_paused = true;
      }
      return;  // EAGAIN: all taken; others (ECONNABORTED, ...) concern that connection only
    }
    ++accepted;
    std::string client = ClientAddress(addr);
    const auto known = per_client.find(client);
    const int from_client = known == per_client.end() ? 0 : known->second;
    if (static_cast<int>(connections.size()) >= max_connections ||
        from_client >= options.max_connections_per_client) {
      ++refused;
      static const std::string kBusy =
          "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n"
          "Content-Length: 21\r\nRetry-After: 1\r\nConnection: close\r\n\r\ntoo many connections\n";
      (void)!send(fd, kBusy.data(), kBusy.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
      DrainAndClose(fd);
      continue;
    }
    const int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    const uint64_t id = next_id++;
    Connection& c = connections[id];
    c.fd = fd;
    c.client = std::move(client);
    c.phase_start = Clock::now();
    c.events = EPOLLIN;
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = id;
    epoll_ctl(epoll_fd, EPOLL_CTL_ADD, fd, &ev);
    ++per_client[c.client];
    ++open;
  }
}

void HttpServer::Impl::OnReadable(uint64_t id, Connection& c) {
  const size_t limit = options.head_limits.max_head_bytes + kReadChunk;
  if (c.in.size() >= limit) return Parse(id, c);
  char buffer[kReadChunk];
  const ssize_t n = recv(c.fd, buffer, std::min(sizeof(buffer), limit - c.in.size()), 0);
  if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
    return Close(id);  // the client left (or the connection broke) before a whole request
  }
  if (n > 0) c.in.append(buffer, static_cast<size_t>(n));
  Parse(id, c);
}

void HttpServer::Impl::Parse(uint64_t id, Connection& c) {
  if (c.in.empty()) return;
  HttpHeadParse p = ParseRequestHead(c.in, options.head_limits);
  switch (p.outcome) {
    case HttpHeadParse::Outcome::kNeedMore:
      return;
    case HttpHeadParse::Outcome::kRefused:
      ++requests;
      return StartSending(id, c, ErrorAnswer(p.status, p.reason, false, false));
    case HttpHeadParse::Outcome::kComplete:
      ++requests;
      c.in.erase(0, p.head_bytes);
      return Dispatch(id, c, p.head);
  }
}

void HttpServer::Impl::Dispatch(uint64_t id, Connection& c, const HttpRequestHead& head) {
  ++c.requests;
  const bool keep_alive =
      head.keep_alive && c.requests < options.keep_alive_max_requests && !stopping;
  const bool head_only = head.method == "HEAD";
  if (head.method != "GET" && !head_only) {
    return StartSending(id, c,
                        ErrorAnswer(405, "only GET and HEAD are served here", false, keep_alive,
                                    {{"Allow", "GET, HEAD"}}));
  }
  const RequestHandler* handler = owner->Find(head.path);
  if (handler == nullptr) {
    return StartSending(id, c, ErrorAnswer(404, not_found, head_only, keep_alive));
  }
  HttpRequest request;
  request.path = head.path;
  request.params = head.params;
  if (const std::string* a = head.Header("authorization")) request.authorization = *a;
  // Without validators to compare, an If-Range never matches: the whole body (RFC 9110 §13.1.5).
  const std::string* range_header = head.Header("if-range") ? nullptr : head.Header("range");
  std::optional<std::string> range;
  if (range_header != nullptr) range = *range_header;
  c.phase = Phase::kHandling;
  SetEvents(id, c, 0);  // nothing is read while the handler runs; hang-ups still show
  const bool queued = pool->TryRun([this, id, handler, request = std::move(request), head_only,
                                    keep_alive, range = std::move(range)] {
    HttpResponse response;
    try {
      response = (*handler)(request);
    } catch (const std::exception& e) {
      // Handlers return statuses; this keeps a stray throw (bad_alloc) from ending the program.
      response = TextResponse(500, absl::StrCat("internal error: ", e.what()));
    } catch (...) {
      response = TextResponse(500, "internal error");
    }
    Finished(id, MakeAnswer(std::move(response), head_only, keep_alive, range ? &*range : nullptr));
  });
  if (!queued) {
    ++busy;
    StartSending(id, c,
                 ErrorAnswer(503, "busy: every handler thread is taken; retry", head_only,
                             keep_alive, {{"Retry-After", "1"}}));
  }
}

void HttpServer::Impl::Finished(uint64_t id, Answer answer) {
  {
    std::lock_guard<std::mutex> lock(finished_mutex);
    finished.emplace_back(id, std::move(answer));
  }
  const uint64_t one = 1;
  (void)!write(wake_fd, &one, sizeof(one));
}

void HttpServer::Impl::TakeFinished() {
  std::vector<std::pair<uint64_t, Answer>> ready;
  {
    std::lock_guard<std::mutex> lock(finished_mutex);
    ready.swap(finished);
  }
  for (auto& [id, answer] : ready) {
    const auto it = connections.find(id);
    if (it == connections.end()) continue;  // the client hung up while its answer was made
    StartSending(id, it->second, std::move(answer));
  }
}

void HttpServer::Impl::StartSending(uint64_t id, Connection& c, Answer answer) {
  c.out = std::move(answer);
  c.sent = 0;
  c.phase = Phase::kSending;
  c.last_progress = Clock::now();
  OnWritable(id, c);
}

void HttpServer::Impl::OnWritable(uint64_t id, Connection& c) {
  const size_t head_size = c.out.head.size();
  const size_t total = head_size + (c.out.end - c.out.begin);
  while (c.sent < total) {
    iovec parts[2];
    int count = 0;
    if (c.sent < head_size) {
      parts[count++] = {const_cast<char*>(c.out.head.data()) + c.sent, head_size - c.sent};
    }
    if (c.out.body != nullptr && c.out.end > c.out.begin) {
      const size_t body_sent = c.sent > head_size ? c.sent - head_size : 0;
      parts[count++] = {const_cast<char*>(c.out.body->data()) + c.out.begin + body_sent,
                        c.out.end - c.out.begin - body_sent};
    }
    msghdr message{};
    message.msg_iov = parts;
    message.msg_iovlen = static_cast<size_t>(count);
    const ssize_t n = sendmsg(c.fd, &message, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
        return SetEvents(id, c, EPOLLOUT);
      }
      return Close(id);
    }
    c.sent += static_cast<size_t>(n);
    c.last_progress = Clock::now();
  }
  if (c.out.close) return Close(id);
  c.out = Answer{};  // releases a shared body at once
  c.phase = Phase::kReading;
  c.phase_start = Clock::now();
  SetEvents(id, c, EPOLLIN);
  Parse(id, c);  // a pipelined request may be waiting
}

void HttpServer::Impl::Sweep(Clock::time_point now) {
  if (accept_paused) {
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = kListenId;
    epoll_ctl(epoll_fd, EPOLL_CTL_MOD, listen_fd, &ev);
    accept_paused = false;
  }
  std::vector<uint64_t> idle, slow_head, slow_reader;
  for (auto& [id, c] : connections) {
    const auto since = now - c.phase_start;
    if (c.phase == Phase::kReading) {
      if (c.in.empty() && since > ToClock(options.keep_alive_timeout)) idle.push_back(id);
      if (!c.in.empty() && since > ToClock(options.request_timeout)) slow_head.push_back(id);
    } else if (c.phase == Phase::kSending &&
               now - c.last_progress > ToClock(options.send_timeout)) {
      slow_reader.push_back(id);
    }
  }
  timeouts += static_cast<int64_t>(idle.size() + slow_head.size() + slow_reader.size());
  for (const uint64_t id : idle) Close(id);
  for (const uint64_t id : slow_reader) Close(id);
  for (const uint64_t id : slow_head) {
    Connection& c = connections[id];
    c.in.clear();
    StartSending(id, c, ErrorAnswer(408, "the request head did not arrive in time", false, false));
  }
}

void HttpServer::Impl::Loop() {
  epoll_event events[64];
  Clock::time_point last_sweep = Clock::now();
  while (!stopping) {
    const int n = epoll_wait(epoll_fd, events, 64, static_cast<int>(kSweepInterval.count()));
    for (int i = 0; i < n && !stopping; ++i) {
      const uint64_t id = events[i].data.u64;
      const uint32_t what = events[i].events;
      if (id == kListenId) {
        Accept();
        continue;
      }
      if (id == kWakeId) {
        uint64_t count = 0;
        (void)!read(wake_fd, &count, sizeof(count));
        continue;
      }
      const auto it = connections.find(id);
      if (it == connections.end()) continue;
      Connection& c = it->second;
      if (what & EPOLLERR) {
        Close(id);
      } else if (c.phase == Phase::kReading && (what & (EPOLLIN | EPOLLHUP))) {
        OnReadable(id, c);
      } else if (c.phase == Phase::kSending && (what & EPOLLOUT)) {
        OnWritable(id, c);
      } else if (what & EPOLLHUP) {
        Close(id);  // gone while its answer was being made
      }
    }
    TakeFinished();
    const Clock::time_point now = Clock::now();
    if (now - last_sweep >= kSweepInterval) {
      Sweep(now);
      last_sweep = now;
    }
  }
}

HttpServer::HttpServer(HttpServerOptions options)
    : options_(std::move(options)), impl_(std::make_unique<Impl>(this, options_)) {}

HttpServer::~HttpServer() = default;

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

HttpServerStats HttpServer::stats() const {
  HttpServerStats s;
  s.connections_open = impl_->open;
  s.connections_accepted = impl_->accepted;
  s.connections_refused = impl_->refused;
  s.requests = impl_->requests;
  s.requests_refused_busy = impl_->busy;
  s.timeouts = impl_->timeouts;
  return s;
}

absl::Status HttpServer::Start() {
  Impl& impl = *impl_;
  const std::string where = absl::StrCat(options_.host, ":", options_.port);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (getaddrinfo(options_.host.c_str(), std::to_string(options_.port).c_str(), &hints, &found) !=
      0) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", where, " (unknown host)"));
  }
  for (addrinfo* a = found; a != nullptr && impl.listen_fd < 0; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) continue;
    // SO_REUSEADDR only: with SO_REUSEPORT a second daemon could bind the same port and take
    // half the scrapes.
    const int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
    if (bind(fd, a->ai_addr, a->ai_addrlen) == 0 && listen(fd, SOMAXCONN) == 0) {
      impl.listen_fd = fd;
    } else {
      close(fd);
    }
  }
  freeaddrinfo(found);
  if (impl.listen_fd < 0) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", where, " (address in use or not local?)"));
  }
  sockaddr_storage bound{};
  socklen_t len = sizeof(bound);
  getsockname(impl.listen_fd, reinterpret_cast<sockaddr*>(&bound), &len);
  port_ =
      ntohs(bound.ss_family == AF_INET6 ? reinterpret_cast<const sockaddr_in6*>(&bound)->sin6_port
                                        : reinterpret_cast<const sockaddr_in*>(&bound)->sin_port);

  // Each connection is a file descriptor; half the process's limit leaves the rest to gRPC and
  // the map files.
  rlimit files{};
  impl.max_connections = std::max(1, options_.max_connections);
  if (getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur != RLIM_INFINITY) {
    impl.max_connections =
        std::min<int64_t>(impl.max_connections, std::max<int64_t>(1, files.rlim_cur / 2));
  }
  std::vector<std::string> paths;
  for (const auto& [path, handler] : exact_) paths.push_back(path);
  for (const auto& [prefix, handler] : prefixes_) paths.push_back(prefix + "...");
  impl.not_found = absl::StrCat("plenoxd serves ", absl::StrJoin(paths, ", "));

  impl.epoll_fd = epoll_create1(EPOLL_CLOEXEC);
  impl.wake_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (impl.epoll_fd < 0 || impl.wake_fd < 0) {
    return absl::UnavailableError(
        absl::StrCat("cannot serve on ", where, ": ", std::strerror(errno)));
  }
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.u64 = kListenId;
  epoll_ctl(impl.epoll_fd, EPOLL_CTL_ADD, impl.listen_fd, &ev);
  ev.data.u64 = kWakeId;
  epoll_ctl(impl.epoll_fd, EPOLL_CTL_ADD, impl.wake_fd, &ev);
  impl.pool = std::make_unique<HandlerPool>(options_.threads, options_.max_queued_requests);
  impl.thread = std::thread([&impl] { impl.Loop(); });
  return absl::OkStatus();
}

}  // namespace plx::web

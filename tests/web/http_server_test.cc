// The side HTTP server (web/http_server.h) on loopback ports: routes, 404 and 405, HEAD,
// keep-alive and pipelining, and every bound it promises against slow, idle, numerous and
// hostile clients: no request body, the request deadline from accept, the head's size and
// header count, connections per client and in all, the handler queue, answers that stall, and
// Range headers that would make an answer larger than its body.
#include "web/http_server.h"

#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "tests/loopback_http.h"
#include "tests/test_util.h"

namespace plx::web {
namespace {

using plx::testing::ConnectLoopback;
using plx::testing::ConnectLoopbackFrom;
using plx::testing::HttpAnswer;
using plx::testing::HttpExchange;
using plx::testing::HttpGet;
using plx::testing::HttpGetAnswer;
using plx::testing::ParseHttpAnswer;
using plx::testing::ReadUntilClosed;
using plx::testing::SendAll;
using plx::testing::Sockets;

HttpResponse Text(const std::string& body) { return HttpResponse{200, "text/plain", body}; }

// Waits up to `limit` for `condition`.
bool Eventually(const std::function<bool()>& condition, absl::Duration limit = absl::Seconds(5)) {
  const absl::Time end = absl::Now() + limit;
  while (absl::Now() < end) {
    if (condition()) return true;
    absl::SleepFor(absl::Milliseconds(10));
  }
  return condition();
}

TEST(HttpServerTest, ServesItsRoutesAndAnswersOtherPaths404) {
  HttpServer server(HttpServerOptions{});
  server.Get("/metrics", [] { return Text("m 1\n"); });
  server.Get("/viewer", [] { return HttpResponse{200, "text/html", "<p>v</p>"}; });
  server.GetPrefix("/files/", [](const HttpRequest& r) { return Text("file " + r.path); });
  ASSERT_TRUE(server.Start().ok());
  ASSERT_GT(server.port(), 0);

  const std::string metrics = HttpGet(server.port(), "/metrics");
  EXPECT_EQ(metrics.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << metrics;
  EXPECT_NE(metrics.find("Content-Type: text/plain\r\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("Content-Length: 4\r\n"), std::string::npos) << metrics;
  EXPECT_EQ(metrics.substr(metrics.size() - 4), "m 1\n") << metrics;
  EXPECT_NE(HttpGet(server.port(), "/viewer").find("<p>v</p>"), std::string::npos);
  EXPECT_EQ(HttpGetAnswer(server.port(), "/files/a%20b").body, "file /files/a b");
  // Exact paths match exactly; prefixes by prefix; nothing else.
  for (const char* path : {"/", "/metricsx", "/metrics/", "/other", "/.*", "/files"}) {
    const HttpAnswer r = HttpGetAnswer(server.port(), path);
    EXPECT_EQ(r.status, 404) << path;
    EXPECT_NE(r.body.find("plenoxd serves /metrics, /viewer, /files/..."), std::string::npos)
        << r.body;
  }
  // The request compose.yaml's health check sends (HTTP/1.0, no Host header).
  EXPECT_EQ(ParseHttpAnswer(HttpExchange(server.port(), "GET /metrics HTTP/1.0\r\n\r\n")).status,
            200);
  // HEAD: the head of GET's answer, its length, no body.
  const std::string head = HttpExchange(server.port(), "HEAD /metrics HTTP/1.0\r\n\r\n");
  EXPECT_NE(head.find("Content-Length: 4\r\n"), std::string::npos) << head;
  EXPECT_EQ(head.substr(head.size() - 4), "\r\n\r\n") << head;
  // Other methods: 405 naming the two.
  const HttpAnswer post =
      ParseHttpAnswer(HttpExchange(server.port(), "DELETE /metrics HTTP/1.0\r\n\r\n"));
  EXPECT_EQ(post.status, 405);
  EXPECT_NE(post.headers.find("allow: get, head"), std::string::npos) << post.headers;
}

// A declared body is refused at once, without the server reading or waiting for it.
TEST(HttpServerTest, RequestBodiesAreRefused) {
  HttpServer server(HttpServerOptions{});
  std::atomic<int> calls{0};
  server.Get("/metrics", [&] {
    ++calls;
    return Text("m 1\n");
  });
  ASSERT_TRUE(server.Start().ok());
  const absl::Time start = absl::Now();
  const HttpAnswer r = ParseHttpAnswer(HttpExchange(
      server.port(), absl::StrCat("POST /metrics HTTP/1.1\r\nContent-Length: 1000000000\r\n\r\n",
                                  std::string(2048, 'x'))));
  EXPECT_EQ(r.status, 413);
  EXPECT_LT(absl::Now() - start, absl::Seconds(2)) << "the server waited for the body";
  EXPECT_EQ(ParseHttpAnswer(HttpExchange(server.port(),
                                         "GET /metrics HTTP/1.1\r\n"
                                         "Transfer-Encoding: chunked\r\n\r\n"))
                .status,
            413);
  EXPECT_EQ(calls.load(), 0);
}

TEST(HttpServerTest, ABusyPortIsAnErrorNotShared) {
  HttpServer first(HttpServerOptions{});
  ASSERT_TRUE(first.Start().ok());
  HttpServerOptions same;
  same.port = first.port();
  HttpServer second(same);
  const absl::Status s = second.Start();
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_NE(s.message().find(absl::StrCat("127.0.0.1:", first.port())), std::string::npos) << s;
}

// A connection that never sends a request is closed after the keep-alive timeout; the read
// below would otherwise wait its own 10 s.
TEST(HttpServerTest, IdleConnectionsAreClosedAfterTheKeepAliveTimeout) {
  HttpServerOptions options;
  options.keep_alive_timeout = absl::Seconds(1);
  HttpServer server(options);
  ASSERT_TRUE(server.Start().ok());
  const int fd = ConnectLoopback(server.port(), absl::Seconds(10));
  ASSERT_GE(fd, 0);
  const absl::Time start = absl::Now();
  char byte = 0;
  const ssize_t n = recv(fd, &byte, 1, 0);
  const absl::Duration waited = absl::Now() - start;
  close(fd);
  EXPECT_EQ(n, 0) << "the server should close the idle connection";
  EXPECT_LT(waited, absl::Seconds(3));
  EXPECT_TRUE(Eventually([&] { return server.stats().connections_open == 0; }));
}

// The audit's slow client: a header line every 100 ms, for ever. The head's deadline runs from
// accept, so the client gets 408 and is closed at the deadline however steadily it trickles.
TEST(HttpServerTest, ATricklingClientIsCutAtTheRequestDeadline) {
  HttpServerOptions options;
  options.request_timeout = absl::Seconds(1);
  HttpServer server(options);
  server.Get("/metrics", [] { return Text("m 1\n"); });
  ASSERT_TRUE(server.Start().ok());
  const int fd = ConnectLoopback(server.port(), absl::Seconds(10));
  ASSERT_GE(fd, 0);
  const absl::Time start = absl::Now();
  ASSERT_TRUE(SendAll(fd, "GET /metrics HTTP/1.1\r\n"));
  std::atomic<bool> stop{false};
  std::thread trickle([&] {
    for (int i = 0; i < 100 && !stop; ++i) {
      absl::SleepFor(absl::Milliseconds(100));
      if (!SendAll(fd, absl::StrCat("X-", i, ": v\r\n"))) break;
    }
  });
  const HttpAnswer answer = ParseHttpAnswer(ReadUntilClosed(fd));
  const absl::Duration took = absl::Now() - start;
  stop = true;
  trickle.join();
  close(fd);
  EXPECT_EQ(answer.status, 408);
  EXPECT_GE(took, absl::Milliseconds(900));
  EXPECT_LT(took, absl::Seconds(3)) << "the deadline must not restart with each byte";
  EXPECT_GE(server.stats().timeouts, 1);
}

TEST(HttpServerTest, HeadersAreCappedInCountAndBytes) {
  HttpServer server(HttpServerOptions{});
  server.Get("/metrics", [] { return Text("m 1\n"); });
  ASSERT_TRUE(server.Start().ok());
  std::string many = "GET /metrics HTTP/1.1\r\n";
  for (int i = 0; i < 100; ++i) absl::StrAppend(&many, "A", i, ": v\r\n");
  EXPECT_EQ(ParseHttpAnswer(HttpExchange(server.port(), many + "\r\n")).status, 431);
  EXPECT_EQ(ParseHttpAnswer(HttpExchange(server.port(), "GET /metrics HTTP/1.1\r\nA: " +
                                                            std::string(9000, 'a') + "\r\n\r\n"))
                .status,
            431);
  EXPECT_EQ(ParseHttpAnswer(
                HttpExchange(server.port(), "GET /" + std::string(9000, 'a') + " HTTP/1.1\r\n\r\n"))
                .status,
            414);
  EXPECT_EQ(HttpGetAnswer(server.port(), "/metrics").status, 200);
}

// One address may hold max_connections_per_client; the next is answered 503 and closed at once,
// while other addresses are served. The total is bounded the same way.
TEST(HttpServerTest, ConnectionsAreCappedPerClientAndInAll) {
  HttpServerOptions options;
  options.max_connections_per_client = 4;
  options.max_connections = 6;
  options.keep_alive_timeout = absl::Seconds(30);  // the held ones stay for the whole test
  HttpServer server(options);
  server.Get("/metrics", [] { return Text("m 1\n"); });
  ASSERT_TRUE(server.Start().ok());
  Sockets held;
  for (int i = 0; i < 4; ++i) held.fds.push_back(ConnectLoopbackFrom("127.0.0.2", server.port()));
  ASSERT_TRUE(Eventually([&] { return server.stats().connections_open == 4; }));
  // The fifth from the same address: refused with a 503, whatever it sends.
  const int fifth = ConnectLoopbackFrom("127.0.0.2", server.port());
  ASSERT_GE(fifth, 0);
  SendAll(fifth, "GET /metrics HTTP/1.1\r\n\r\n");
  const HttpAnswer refused = ParseHttpAnswer(ReadUntilClosed(fifth));
  close(fifth);
  EXPECT_EQ(refused.status, 503);
  EXPECT_NE(refused.headers.find("retry-after: 1"), std::string::npos);
  // Another address is served (127.0.0.1: HttpGetAnswer's).
  EXPECT_EQ(HttpGetAnswer(server.port(), "/metrics").status, 200);
  // Two more from a third address fill the total of 6; the seventh is refused.
  held.fds.push_back(ConnectLoopbackFrom("127.0.0.3", server.port()));
  held.fds.push_back(ConnectLoopbackFrom("127.0.0.3", server.port()));
  ASSERT_TRUE(Eventually([&] { return server.stats().connections_open == 6; }));
  EXPECT_EQ(HttpGetAnswer(server.port(), "/metrics").status, 503);
  EXPECT_EQ(server.stats().connections_refused, 2);
  // Closing one frees its place.
  close(held.fds.back());
  held.fds.pop_back();
  ASSERT_TRUE(Eventually([&] { return server.stats().connections_open == 5; }));
  EXPECT_EQ(HttpGetAnswer(server.port(), "/metrics").status, 200);
}

// Handlers run on `threads` threads with at most `max_queued_requests` waiting: a request past
// that is answered 503 at once instead of queueing without bound.
TEST(HttpServerTest, TheHandlerQueueIsBounded) {
  HttpServerOptions options;
  options.threads = 1;
  options.max_queued_requests = 1;
  HttpServer server(options);
  std::mutex mutex;
  std::condition_variable released;
  bool release = false;
  std::atomic<int> started{0};
  server.Get("/slow", [&] {
    ++started;
    std::unique_lock<std::mutex> lock(mutex);
    released.wait(lock, [&] { return release; });
    return Text("done\n");
  });
  ASSERT_TRUE(server.Start().ok());
  HttpAnswer first, second;
  std::thread a([&] { first = HttpGetAnswer(server.port(), "/slow"); });
  ASSERT_TRUE(Eventually([&] { return started == 1; }));
  std::thread b([&] { second = HttpGetAnswer(server.port(), "/slow"); });
  ASSERT_TRUE(Eventually([&] { return server.stats().requests == 2; }));
  const absl::Time start = absl::Now();
  const HttpAnswer third = HttpGetAnswer(server.port(), "/slow");
  EXPECT_EQ(third.status, 503);
  EXPECT_NE(third.headers.find("retry-after: 1"), std::string::npos);
  EXPECT_LT(absl::Now() - start, absl::Seconds(2)) << "the busy answer should not wait";
  {
    std::lock_guard<std::mutex> lock(mutex);
    release = true;
  }
  released.notify_all();
  a.join();
  b.join();
  EXPECT_EQ(first.status, 200);
  EXPECT_EQ(second.status, 200);
  EXPECT_EQ(server.stats().requests_refused_busy, 1);
}

// A client that stops reading an answer is dropped after send_timeout, and the connection's
// place is freed.
TEST(HttpServerTest, AnAnswerThatStallsIsDropped) {
  HttpServerOptions options;
  options.send_timeout = absl::Seconds(1);
  HttpServer server(options);
  const auto big = std::make_shared<const std::string>(size_t{64} << 20, 'z');
  server.Get("/big", [big] {
    HttpResponse r;
    r.content_type = "application/octet-stream";
    r.shared_body = big;
    return r;
  });
  ASSERT_TRUE(server.Start().ok());
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int small = 4096;  // so the kernel's buffers cannot take the whole answer
  setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof(small));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(server.port()));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  ASSERT_TRUE(SendAll(fd, "GET /big HTTP/1.1\r\n\r\n"));
  EXPECT_TRUE(Eventually([&] { return server.stats().connections_open == 1; }));
  EXPECT_TRUE(Eventually([&] { return server.stats().connections_open == 0; }, absl::Seconds(5)))
      << "a stalled answer should be dropped after about a second";
  EXPECT_GE(server.stats().timeouts, 1);
  close(fd);
}

TEST(HttpServerTest, KeepAliveServesPipelinedRequestsInOrderUpToTheCap) {
  HttpServerOptions options;
  options.keep_alive_max_requests = 3;
  HttpServer server(options);
  std::atomic<int> n{0};
  server.Get("/n", [&] { return Text(absl::StrCat("n=", ++n, "\n")); });
  ASSERT_TRUE(server.Start().ok());
  // Four requests in one write: three answers, the third closing the connection.
  const std::string raw =
      HttpExchange(server.port(),
                   "GET /n HTTP/1.1\r\n\r\nGET /n HTTP/1.1\r\n\r\nGET /n HTTP/1.1\r\n\r\n"
                   "GET /n HTTP/1.1\r\n\r\n");
  const size_t one = raw.find("n=1\n"), two = raw.find("n=2\n"), three = raw.find("n=3\n");
  ASSERT_NE(one, std::string::npos) << raw;
  ASSERT_NE(two, std::string::npos) << raw;
  ASSERT_NE(three, std::string::npos) << raw;
  EXPECT_LT(one, two);
  EXPECT_LT(two, three);
  EXPECT_EQ(raw.find("n=4"), std::string::npos) << raw;
  auto count = [&raw](const std::string& what) {
    int n = 0;
    for (size_t at = raw.find(what); at != std::string::npos; at = raw.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("Connection: keep-alive"), 2) << raw;
  EXPECT_EQ(count("Connection: close"), 1) << raw;
}

// The audit's amplification: 700 overlapping ranges of an 850 KB script made a 595 MB answer.
// Now any Range gets one part at most, sent from the handler's one copy of the body.
TEST(HttpServerTest, RangesNeverMakeAnAnswerLargerThanItsBody) {
  HttpServerOptions options;
  options.threads = 4;
  HttpServer server(options);
  std::string text(850573, 'a');
  for (size_t i = 0; i < text.size(); ++i) text[i] = static_cast<char>('a' + i % 26);
  server.Get("/three.min.js", [&text] {
    HttpResponse r;
    r.content_type = "text/javascript";
    r.shared_body = UnownedBody(text);
    return r;
  });
  ASSERT_TRUE(server.Start().ok());
  const int port = server.port();

  std::string amplifier = "Range: bytes=0-850572";
  for (int i = 0; i < 700; ++i) amplifier += ",0-850572";
  amplifier += "\r\n";
  const int64_t rss_before = plx::testing::ResidentBytes();
  std::vector<HttpAnswer> answers(8);
  std::vector<std::thread> clients;
  for (HttpAnswer& a : answers) {
    clients.emplace_back([&] { a = HttpGetAnswer(port, "/three.min.js", amplifier); });
  }
  for (std::thread& t : clients) t.join();
  const int64_t rss_after = plx::testing::ResidentBytes();
  for (const HttpAnswer& a : answers) {
    EXPECT_EQ(a.status, 206);
    EXPECT_NE(a.headers.find("content-range: bytes 0-850572/850573"), std::string::npos);
    EXPECT_EQ(a.headers.find("multipart"), std::string::npos);
    EXPECT_EQ(a.body, text);
  }
  // Eight answers of 850 KB each are read by this process too; 595 MB each was the old cost.
  EXPECT_LT(rss_after - rss_before, int64_t{64} << 20);

  // One range: that part. Several: the span covering them. Past the end: 416. Not understood,
  // or behind an If-Range: the whole body.
  HttpAnswer a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=10-19\r\n");
  EXPECT_EQ(a.status, 206);
  EXPECT_EQ(a.body, text.substr(10, 10));
  a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=100-109, 10-19, 15-16\r\n");
  EXPECT_EQ(a.status, 206);
  EXPECT_EQ(a.body, text.substr(10, 100));
  a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=-5\r\n");
  EXPECT_EQ(a.body, text.substr(text.size() - 5));
  a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=0-99999999999999999999999999\r\n");
  EXPECT_EQ(a.status, 206);
  EXPECT_EQ(a.body.size(), text.size());
  a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=850573-\r\n");
  EXPECT_EQ(a.status, 416);
  EXPECT_NE(a.headers.find("content-range: bytes */850573"), std::string::npos);
  EXPECT_TRUE(a.body.empty());
  a = HttpGetAnswer(port, "/three.min.js", "Range: lines=1-2\r\n");
  EXPECT_EQ(a.status, 200);
  EXPECT_EQ(a.body.size(), text.size());
  a = HttpGetAnswer(port, "/three.min.js", "Range: bytes=0-1\r\nIf-Range: \"v1\"\r\n");
  EXPECT_EQ(a.status, 200);
  // HEAD with a range: the part's head, no body.
  const HttpAnswer head = ParseHttpAnswer(
      HttpExchange(port, "HEAD /three.min.js HTTP/1.0\r\nRange: bytes=0-9,20-29\r\n\r\n"));
  EXPECT_EQ(head.status, 206);
  EXPECT_NE(head.headers.find("content-length: 30"), std::string::npos) << head.headers;
  EXPECT_TRUE(head.body.empty());
}

// A handler's header with a line break is not sent (it would split the head).
TEST(HttpServerTest, HeadersThatWouldSplitTheHeadAreDropped) {
  HttpServer server(HttpServerOptions{});
  server.Get("/h", [] {
    return HttpResponse{
        200, "text/plain", "ok\n", {{"X-Good", "1"}, {"X-Bad", "a\r\nSet-Cookie: x"}}};
  });
  ASSERT_TRUE(server.Start().ok());
  const HttpAnswer a = HttpGetAnswer(server.port(), "/h");
  EXPECT_EQ(a.status, 200);
  EXPECT_NE(a.headers.find("x-good: 1"), std::string::npos);
  EXPECT_EQ(a.headers.find("set-cookie"), std::string::npos);
  EXPECT_EQ(a.headers.find("x-bad"), std::string::npos);
}

}  // namespace
}  // namespace plx::web

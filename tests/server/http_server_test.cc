// The side HTTP server (web/http_server.h) on loopback ports: routes, 404s, bounded request
// bodies, a busy port, and connections that sit idle: they must neither hold up a scrape nor
// stay open past the keep-alive timeout.
#include "web/http_server.h"

#include <unistd.h>

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

using web::HttpResponse;
using web::HttpServer;
using web::HttpServerOptions;

// Sockets opened by a test, closed when it ends.
struct Sockets {
  std::vector<int> fds;
  ~Sockets() {
    for (int fd : fds) close(fd);
  }
};

TEST(HttpServerTest, ServesItsRoutesAndAnswersOtherPaths404) {
  HttpServer server(HttpServerOptions{});
  server.Get("/metrics", [] { return HttpResponse{200, "text/plain", "m 1\n"}; });
  server.Get("/viewer", [] { return HttpResponse{200, "text/html", "<p>v</p>"}; });
  ASSERT_TRUE(server.Start().ok());
  ASSERT_GT(server.port(), 0);

  const std::string metrics = HttpGet(server.port(), "/metrics");
  EXPECT_EQ(metrics.rfind("HTTP/1.1 200", 0), 0u) << metrics;
  EXPECT_NE(metrics.find("Content-Type: text/plain"), std::string::npos) << metrics;
  EXPECT_EQ(metrics.substr(metrics.size() - 4), "m 1\n") << metrics;
  const std::string viewer = HttpGet(server.port(), "/viewer");
  EXPECT_NE(viewer.find("<p>v</p>"), std::string::npos) << viewer;
  // Paths match exactly: no prefixes, no regexes.
  for (const char* path : {"/", "/metricsx", "/metrics/", "/other", "/.*"}) {
    const std::string r = HttpGet(server.port(), path);
    EXPECT_EQ(r.rfind("HTTP/1.1 404", 0), 0u) << path << ": " << r;
    EXPECT_NE(r.find("plenoxd serves /metrics, /viewer"), std::string::npos) << r;
  }
  // The request compose.yaml's health check sends (HTTP/1.0, no Host header).
  const std::string probe = HttpExchange(server.port(), "GET /metrics HTTP/1.0\r\n\r\n");
  EXPECT_EQ(probe.rfind("HTTP/1.1 200", 0), 0u) << probe;
}

// A client that declares a large body is refused without the server buffering it.
TEST(HttpServerTest, RequestBodiesAreBounded) {
  HttpServerOptions options;
  options.max_body_bytes = 1024;
  options.read_timeout = absl::Seconds(1);  // how long it then waits for the rest of the body
  HttpServer server(options);
  server.Get("/metrics", [] { return HttpResponse{200, "text/plain", "m 1\n"}; });
  ASSERT_TRUE(server.Start().ok());
  const std::string r = HttpExchange(
      server.port(), absl::StrCat("POST /metrics HTTP/1.0\r\nContent-Length: 1000000000\r\n\r\n",
                                  std::string(2048, 'x')));
  EXPECT_EQ(r.rfind("HTTP/1.1 413", 0), 0u) << r;
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

// An idle connection (no request ever sent) is closed by the server after the keep-alive
// timeout, freeing its thread; the read below would otherwise wait its own 10 s.
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
  EXPECT_LT(waited, absl::Seconds(4));
}

// The audit's case: 8 idle connections to the daemon's metrics port delayed a scrape by 16 s
// (one connection at a time, 2 s each). Now the scrape is served at once by another thread.
TEST(HttpServerTest, DaemonScrapeIsNotHeldUpByIdleConnections) {
  DaemonOptions o = TestDaemonOptions(ScratchDir("plx_srv_http_idle"));
  o.metrics_port = 0;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  ASSERT_GT(port, 0);
  Sockets idle;
  for (int i = 0; i < 8; ++i) {
    const int fd = ConnectLoopback(port);
    ASSERT_GE(fd, 0) << "connection " << i;
    idle.fds.push_back(fd);
  }
  const absl::Time start = absl::Now();
  const std::string body = HttpGet(port, "/metrics");
  const absl::Duration took = absl::Now() - start;
  EXPECT_EQ(body.rfind("HTTP/1.1 200", 0), 0u) << body.substr(0, 200);
  EXPECT_NE(body.find("\nplenoxd_serving 1\n"), std::string::npos);
  EXPECT_LT(took, absl::Seconds(2)) << "the scrape waited behind the idle connections";
}

}  // namespace
}  // namespace plx::server::testing

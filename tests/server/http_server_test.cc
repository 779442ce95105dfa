// plenoxd's HTTP port (/metrics and the viewer) against the audit's hostile clients: many idle
// and trickling connections must not hold up a scrape or a viewer call, and no Range header on
// any endpoint may make an answer larger than its body (web/http_server.h has the bounds; the
// server's own tests are tests/web/http_server_test.cc).
#include <atomic>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "tests/server/viewer_fixture.h"

namespace plx::server::testing {
namespace {

// Times one GET; its status.
int TimedGet(int port, const std::string& path, absl::Duration* took) {
  const absl::Time start = absl::Now();
  const int status = HttpGetAnswer(port, path).status;
  *took = absl::Now() - start;
  return status;
}

// 50 clients trickle a header line every 200 ms and 200 sit idle, spread over eight loopback
// addresses (the per-client cap is 32): a scrape and a viewer call from another address are
// each answered within a second, at once and again while all of them are still held.
TEST(HttpServerTest, ScrapesAndViewerCallsAnswerWhileHostileClientsHoldConnections) {
  PLX_SKIP_WITHOUT_THREE_JS();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_http_hostile"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  ASSERT_GT(port, 0);

  Sockets idle, trickling;
  for (int i = 0; i < 250; ++i) {
    const std::string from = absl::StrCat("127.0.0.", 2 + i % 8);
    const int fd = ConnectLoopbackFrom(from.c_str(), port);
    ASSERT_GE(fd, 0) << "connection " << i;
    (i < 50 ? trickling : idle).fds.push_back(fd);
  }
  for (const int fd : trickling.fds) SendAll(fd, "GET /metrics HTTP/1.1\r\n");
  std::atomic<bool> stop{false};
  std::thread trickle([&] {
    for (int line = 0; line < 20 && !stop; ++line) {
      absl::SleepFor(absl::Milliseconds(200));
      for (const int fd : trickling.fds) SendAll(fd, absl::StrCat("X-", line, ": v\r\n"));
    }
  });
  for (int round = 0; round < 2; ++round) {
    absl::Duration scrape, maps;
    EXPECT_EQ(TimedGet(port, "/metrics", &scrape), 200);
    EXPECT_EQ(TimedGet(port, "/viewer/api/maps", &maps), 200);
    EXPECT_LT(scrape, absl::Seconds(1)) << "round " << round;
    EXPECT_LT(maps, absl::Seconds(1)) << "round " << round;
    absl::SleepFor(absl::Milliseconds(700));  // still within the 2 s idle and 5 s head bounds
  }
  stop = true;
  trickle.join();
  // None of them got further than its deadline: every trickler was answered 408 and closed.
  for (const int fd : trickling.fds) {
    EXPECT_EQ(ParseHttpAnswer(plx::testing::ReadUntilClosed(fd)).status, 408);
  }
  // And /metrics counts them (with the idle ones, closed after 2 s).
  const std::string metrics = HttpGetAnswer(port, "/metrics").body;
  const std::string name = "\nplenoxd_http_timeouts_total ";
  const size_t at = metrics.find(name);
  ASSERT_NE(at, std::string::npos) << metrics;
  EXPECT_GE(std::atoll(metrics.c_str() + at + name.size()), 250);
}

// Multi-range, overlapping-range, huge and unsatisfiable Range headers on every endpoint:
// each answer is 200, one part (206) or 416, never multipart, never larger than the body, and
// the daemon's memory stays put (700 overlapping ranges of three.js took it up by 900 MB).
TEST(HttpServerTest, RangesOnEveryEndpointGiveOnePartAtMost) {
  PLX_SKIP_WITHOUT_THREE_JS();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartWithMaps({"room"}, ViewerDaemonOptions("plx_srv_http_ranges"));
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->daemon->metrics_port();
  const std::vector<std::string> endpoints = {"/metrics",
                                              "/viewer/",
                                              "/viewer/viewer.js",
                                              "/viewer/viewer.css",
                                              "/viewer/three/three.min.js",
                                              "/viewer/three/OrbitControls.js",
                                              "/viewer/api/maps",
                                              "/viewer/api/points?map=room",
                                              "/viewer/api/mesh?map=room",
                                              "/viewer/api/trajectory?map=room",
                                              RenderQuery("room", 5, 64, 48, "color")};
  std::string overlapping = "bytes=0-99999999";
  for (int i = 0; i < 700; ++i) overlapping += ",0-99999999";
  std::string scattered = "bytes=0-0";
  for (int i = 1; i < 700; ++i) absl::StrAppend(&scattered, ",", i * 7, "-", i * 7 + 3);
  const std::vector<std::string> ranges = {overlapping, scattered, "bytes=0-18446744073709551616",
                                           "bytes=-1,-2,-3,0-", "bytes=999999999-"};
  const int64_t rss_before = plx::testing::ResidentBytes();
  for (const std::string& path : endpoints) {
    const HttpAnswer whole = HttpGetAnswer(port, path);
    ASSERT_EQ(whole.status, 200) << path;
    for (const std::string& range : ranges) {
      const HttpAnswer a = HttpGetAnswer(port, path, "Range: " + range + "\r\n");
      const std::string what = absl::StrCat(path, " with ", range.substr(0, 40));
      EXPECT_TRUE(a.status == 200 || a.status == 206 || a.status == 416)
          << what << ": " << a.status;
      EXPECT_EQ(a.headers.find("multipart"), std::string::npos) << what;
      // Renders and metrics change between calls; their sizes only bound each other.
      EXPECT_LE(a.body.size(), whole.body.size() + 4096) << what;
    }
    // Past the end: 416 (every body here is under 999 999 999 bytes).
    EXPECT_EQ(HttpGetAnswer(port, path, "Range: bytes=999999999-\r\n").status, 416) << path;
  }
  EXPECT_LT(plx::testing::ResidentBytes() - rss_before, int64_t{200} << 20);
}

}  // namespace
}  // namespace plx::server::testing

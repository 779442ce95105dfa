// The request-head parser and the Range rule of the side HTTP server (web/http_request.h).
#include "web/http_request.h"

#include <string>

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"

namespace plx::web {
namespace {

using Outcome = HttpHeadParse::Outcome;

TEST(HttpRequestTest, ParsesTheRequestLineTheQueryAndTheHeaders) {
  const std::string bytes =
      "GET /viewer/api/render?map=a%20b&pose=1+2&map=second&flag HTTP/1.1\r\n"
      "Host: 127.0.0.1\r\nAuthorization:  Bearer x y \r\nRange: bytes=0-9\r\n\r\nGET /next";
  const HttpHeadParse p = ParseRequestHead(bytes, HttpHeadLimits{});
  ASSERT_EQ(p.outcome, Outcome::kComplete) << p.reason;
  EXPECT_EQ(p.head_bytes, bytes.find("GET /next"));  // the pipelined request stays
  EXPECT_EQ(p.head.method, "GET");
  EXPECT_EQ(p.head.path, "/viewer/api/render");
  EXPECT_EQ(p.head.params.at("map"), "a b");  // the first value of a repeated name
  EXPECT_EQ(p.head.params.at("pose"), "1 2");
  EXPECT_EQ(p.head.params.at("flag"), "");
  ASSERT_NE(p.head.Header("authorization"), nullptr);
  EXPECT_EQ(*p.head.Header("authorization"), "Bearer x y");
  EXPECT_EQ(*p.head.Header("range"), "bytes=0-9");
  EXPECT_EQ(p.head.Header("cookie"), nullptr);
  EXPECT_TRUE(p.head.keep_alive);
}

TEST(HttpRequestTest, KeepAliveOnlyForHttp11WithoutConnectionClose) {
  auto keep_alive = [](const std::string& bytes) {
    const HttpHeadParse p = ParseRequestHead(bytes, HttpHeadLimits{});
    EXPECT_EQ(p.outcome, Outcome::kComplete) << bytes;
    return p.head.keep_alive;
  };
  EXPECT_TRUE(keep_alive("GET / HTTP/1.1\r\n\r\n"));
  EXPECT_FALSE(keep_alive("GET / HTTP/1.1\r\nConnection: Keep-Alive, Close\r\n\r\n"));
  EXPECT_FALSE(keep_alive("GET / HTTP/1.0\r\n\r\n"));
  EXPECT_FALSE(keep_alive("GET / HTTP/1.0\r\nConnection: keep-alive\r\n\r\n"));
  // Bare LF line ends (RFC 9112 §2.2) and empty lines before the request line.
  EXPECT_TRUE(keep_alive("\r\n\nGET / HTTP/1.1\nHost: x\n\n"));
}

TEST(HttpRequestTest, WaitsForTheRestOfAnIncompleteHead) {
  for (const char* partial : {"", "G", "GET / HTTP/1.1", "GET / HTTP/1.1\r\nHost: x\r\n"}) {
    EXPECT_EQ(ParseRequestHead(partial, HttpHeadLimits{}).outcome, Outcome::kNeedMore) << partial;
  }
}

TEST(HttpRequestTest, RefusesHeadsPastTheLimitsBeforeTheyEnd) {
  HttpHeadLimits limits;
  limits.max_head_bytes = 256;
  limits.max_headers = 4;
  // A request line longer than the whole head may be: 414 without waiting for its end.
  HttpHeadParse p = ParseRequestHead("GET /" + std::string(300, 'a'), limits);
  EXPECT_EQ(p.outcome, Outcome::kRefused);
  EXPECT_EQ(p.status, 414);
  // Headers that pass the byte limit, complete or not: 431.
  const std::string many_bytes = "GET / HTTP/1.1\r\nX: " + std::string(300, 'b');
  EXPECT_EQ(ParseRequestHead(many_bytes, limits).status, 431);
  EXPECT_EQ(ParseRequestHead(many_bytes + "\r\n\r\n", limits).status, 431);
  // Five header lines when four are allowed, before the head ends (a trickling client).
  std::string lines = "GET / HTTP/1.1\r\n";
  for (int i = 0; i < 5; ++i) absl::StrAppend(&lines, "A", i, ": v\r\n");
  p = ParseRequestHead(lines, limits);
  EXPECT_EQ(p.outcome, Outcome::kRefused);
  EXPECT_EQ(p.status, 431);
  EXPECT_EQ(ParseRequestHead(lines + "\r\n", limits).status, 431);
  // Four are fine.
  lines = "GET / HTTP/1.1\r\n";
  for (int i = 0; i < 4; ++i) absl::StrAppend(&lines, "A", i, ": v\r\n");
  EXPECT_EQ(ParseRequestHead(lines + "\r\n", limits).outcome, Outcome::kComplete);
}

TEST(HttpRequestTest, RefusesMalformedRequestsAndBodies) {
  const struct {
    const char* bytes;
    int status;
  } cases[] = {
      {"GET /\r\n\r\n", 400},                   // no version
      {"GET  / HTTP/1.1\r\n\r\n", 400},         // two spaces
      {"G(T / HTTP/1.1\r\n\r\n", 400},          // not a token
      {"GET http://x/ HTTP/1.1\r\n\r\n", 400},  // absolute form: not a proxy
      {"GET * HTTP/1.1\r\n\r\n", 400},
      {"GET / HTTP/2.0\r\n\r\n", 505},
      {"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n", 505},  // an HTTP/2 preface
      {"GET / FTP/1.1\r\n\r\n", 400},
      {"GET /%zz HTTP/1.1\r\n\r\n", 400},    // bad escape
      {"GET /a%00b HTTP/1.1\r\n\r\n", 400},  // NUL
      {"GET /?x=%4 HTTP/1.1\r\n\r\n", 400},
      {"GET / HTTP/1.1\r\nNo colon\r\n\r\n", 400},
      {"GET / HTTP/1.1\r\nBad name: v\r\n\r\n", 400},
      {"GET / HTTP/1.1\r\nA: v\r\n folded\r\n\r\n", 400},
      {"GET / HTTP/1.1\r\nA: v\rw\r\n\r\n", 400},  // a bare CR inside a value
      {"GET / HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello", 413},
      {"GET / HTTP/1.1\r\nContent-Length: x\r\n\r\n", 400},
      {"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 413},
  };
  for (const auto& c : cases) {
    const HttpHeadParse p = ParseRequestHead(c.bytes, HttpHeadLimits{});
    EXPECT_EQ(p.outcome, Outcome::kRefused) << c.bytes;
    EXPECT_EQ(p.status, c.status) << c.bytes << ": " << p.reason;
    EXPECT_FALSE(p.reason.empty());
  }
  // An empty body is no body.
  EXPECT_EQ(
      ParseRequestHead("GET / HTTP/1.1\r\nContent-Length: 0\r\n\r\n", HttpHeadLimits{}).outcome,
      Outcome::kComplete);
}

TEST(HttpRequestTest, ARangeIsAtMostOnePartOfTheBody) {
  using Kind = ByteRange::Kind;
  auto part = [](const std::string& header, uint64_t size) {
    const ByteRange r = ParseByteRange(header, size);
    EXPECT_EQ(r.kind, Kind::kPart) << header;
    return std::make_pair(r.first, r.last);
  };
  EXPECT_EQ(part("bytes=0-9", 100), std::make_pair(uint64_t{0}, uint64_t{9}));
  EXPECT_EQ(part("bytes=90-", 100), std::make_pair(uint64_t{90}, uint64_t{99}));
  EXPECT_EQ(part("bytes=-10", 100), std::make_pair(uint64_t{90}, uint64_t{99}));
  EXPECT_EQ(part("bytes=-1000", 100), std::make_pair(uint64_t{0}, uint64_t{99}));
  EXPECT_EQ(part("bytes=50-1000", 100), std::make_pair(uint64_t{50}, uint64_t{99}));
  EXPECT_EQ(part("Bytes = 1-2 ", 100), std::make_pair(uint64_t{1}, uint64_t{2}));
  // Past 64 bits: saturated, so clipped to the body, never wrapped around.
  EXPECT_EQ(part("bytes=0-99999999999999999999999999", 100),
            std::make_pair(uint64_t{0}, uint64_t{99}));
  // Several ranges, overlapping or not, in any number: the one span covering them.
  EXPECT_EQ(part("bytes=10-19,40-49", 100), std::make_pair(uint64_t{10}, uint64_t{49}));
  std::string amplifier = "bytes=0-99";
  for (int i = 0; i < 700; ++i) amplifier += ",0-99";
  EXPECT_EQ(part(amplifier, 100), std::make_pair(uint64_t{0}, uint64_t{99}));
  // Ranges past the end are dropped, the rest served.
  EXPECT_EQ(part("bytes=500-600,5-6", 100), std::make_pair(uint64_t{5}, uint64_t{6}));

  EXPECT_EQ(ParseByteRange("bytes=100-", 100).kind, Kind::kUnsatisfiable);
  EXPECT_EQ(ParseByteRange("bytes=99999999999999999999999-", 100).kind, Kind::kUnsatisfiable);
  EXPECT_EQ(ParseByteRange("bytes=-0", 100).kind, Kind::kUnsatisfiable);
  EXPECT_EQ(ParseByteRange("bytes=0-0", 0).kind, Kind::kUnsatisfiable);
  // Not understood: ignored, the whole body.
  for (const char* ignored : {"", "bytes", "bytes=", "bytes=,", "items=0-1", "bytes=5-1",
                              "bytes=a-b", "bytes=1-2,x", "bytes=--1", "bytes=0-1-2"}) {
    EXPECT_EQ(ParseByteRange(ignored, 100).kind, Kind::kWhole) << ignored;
  }
}

TEST(HttpRequestTest, PercentDecoding) {
  std::string out;
  EXPECT_TRUE(PercentDecode("a%2Fb%2fc+d", false, &out));
  EXPECT_EQ(out, "a/b/c+d");
  EXPECT_TRUE(PercentDecode("a+b", true, &out));
  EXPECT_EQ(out, "a b");
  EXPECT_FALSE(PercentDecode("%", false, &out));
  EXPECT_FALSE(PercentDecode("%a", false, &out));
  EXPECT_FALSE(PercentDecode("%g0", false, &out));
  EXPECT_FALSE(PercentDecode("%00", false, &out));
}

}  // namespace
}  // namespace plx::web

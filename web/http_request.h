// The HTTP/1.1 request head as the side HTTP server (web/http_server.h) reads it: the request
// line and the header fields, bounded in bytes and in count, and the one header it acts on
// beyond routing, Range. Pure functions over bytes, so the parser is unit-tested and fuzzed
// (fuzz/http_request_fuzzer.cc) without sockets.
//
// Only what the server's GET/HEAD routes need is accepted: an origin-form target ("/path?q"),
// HTTP/1.0 or 1.1, no request body (a declared body is refused: no route reads one, and reading
// it would let a client make the server buffer or wait for it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/string_view.h"

namespace plx::web {

struct HttpHeadLimits {
  // The request line and every header line together, line ends included. Browsers send well
  // under 2 KiB; a longer head is refused with 431 (414 when the request line alone is longer).
  size_t max_head_bytes = 8192;
  // Header fields after the request line: browsers send about 15; more is refused with 431.
  int max_headers = 64;
};

struct HttpRequestHead {
  std::string method;  // as sent (methods are case-sensitive): "GET", "HEAD", ...
  std::string path;    // percent-decoded, without the query
  // The query's parameters, percent-decoded ('+' is a space); a name given twice keeps its
  // first value.
  std::map<std::string, std::string> params;
  int minor_version = 1;  // HTTP/1.<minor_version>
  // Field names lower-cased, values without surrounding whitespace, in the order sent.
  std::vector<std::pair<std::string, std::string>> headers;
  bool keep_alive = true;  // HTTP/1.1 unless "Connection: close"; HTTP/1.0 never

  // The first value of a header (`name` lower-case), or nullptr.
  const std::string* Header(absl::string_view name) const;
};

struct HttpHeadParse {
  enum class Outcome {
    kNeedMore,  // no complete head yet, and nothing wrong with what has come so far
    kComplete,  // `head` holds it; its bytes are the first `head_bytes` of the input
    kRefused,   // answer `status` with `reason` and close the connection
  };
  Outcome outcome = Outcome::kNeedMore;
  HttpRequestHead head;
  size_t head_bytes = 0;
  int status = 0;
  std::string reason;
};

// Parses the request head at the start of `bytes` (what a connection has received so far;
// bytes after the head are a pipelined next request and are left alone). Decides as early as
// it can: a request line or head past the limits is refused before the rest arrives.
HttpHeadParse ParseRequestHead(absl::string_view bytes, const HttpHeadLimits& limits);

// What a Range header asks of a body of `size` bytes (RFC 9110 §14.2), collapsed to at most one
// part so that an answer is never larger than its body: several ranges (overlapping or not, in
// any number) become the one span that covers them all, which RFC 9110 allows a server to send
// instead. A header that does not parse, or names a unit other than bytes, is ignored (the whole
// body, 200), as RFC 9110 asks.
struct ByteRange {
  enum class Kind { kWhole, kPart, kUnsatisfiable };
  Kind kind = Kind::kWhole;
  uint64_t first = 0;  // kPart: the first and last byte, inclusive
  uint64_t last = 0;
};
ByteRange ParseByteRange(absl::string_view header, uint64_t size);

// Decodes %XX escapes (and '+' as a space when `plus_is_space`); false on a malformed escape
// or a decoded NUL.
bool PercentDecode(absl::string_view in, bool plus_is_space, std::string* out);

// The reason phrase of the status codes the server sends ("Unknown" otherwise).
const char* HttpReasonPhrase(int status);

}  // namespace plx::web

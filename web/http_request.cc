#include "web/http_request.h"

#include <algorithm>
#include <limits>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"

namespace plx::web {
namespace {

HttpHeadParse Refuse(int status, std::string reason) {
  HttpHeadParse p;
  p.outcome = HttpHeadParse::Outcome::kRefused;
  p.status = status;
  p.reason = std::move(reason);
  return p;
}

// RFC 9110 §5.6.2: the characters of a method or a field name.
bool IsToken(absl::string_view s) {
  if (s.empty()) return false;
  for (const char c : s) {
    const bool ok = absl::ascii_isalnum(static_cast<unsigned char>(c)) ||
                    absl::StrContains("!#$%&'*+-.^_`|~", c);
    if (!ok) return false;
  }
  return true;
}

// A field value may hold visible characters, spaces and tabs, and obs-text; never other
// controls (a bare CR could split a header for a proxy that reads it differently).
bool IsFieldValue(absl::string_view s) {
  for (const char c : s) {
    const unsigned char u = static_cast<unsigned char>(c);
    if ((u < 0x20 && c != '\t') || u == 0x7f) return false;
  }
  return true;
}

// One line without its end: RFC 9112 §2.2 lets a server take a bare LF as a line end.
absl::string_view WithoutCr(absl::string_view line) {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  return line;
}

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool ParseTarget(absl::string_view target, HttpRequestHead* head) {
  if (target.empty() || target[0] != '/') return false;  // origin-form only
  const size_t query_at = target.find('?');
  const absl::string_view path = target.substr(0, query_at);
  if (!PercentDecode(path, /*plus_is_space=*/false, &head->path)) return false;
  if (query_at == absl::string_view::npos) return true;
  for (const absl::string_view pair : absl::StrSplit(target.substr(query_at + 1), '&')) {
    if (pair.empty()) continue;
    const size_t eq = pair.find('=');
    std::string name, value;
    if (!PercentDecode(pair.substr(0, eq), true, &name)) return false;
    if (eq != absl::string_view::npos && !PercentDecode(pair.substr(eq + 1), true, &value)) {
      return false;
    }
    head->params.emplace(std::move(name), std::move(value));  // the first value stays
  }
  return true;
}

HttpHeadParse ParseRequestLine(absl::string_view line, HttpHeadParse parse) {
  const std::vector<absl::string_view> parts = absl::StrSplit(line, ' ');
  if (parts.size() != 3 || !IsToken(parts[0])) {
    return Refuse(400, "malformed request line");
  }
  if (parts[2] == "HTTP/1.1") {
    parse.head.minor_version = 1;
  } else if (parts[2] == "HTTP/1.0") {
    parse.head.minor_version = 0;
  } else if (absl::StartsWith(parts[2], "HTTP/")) {
    return Refuse(505, "only HTTP/1.0 and HTTP/1.1 are served here");
  } else {
    return Refuse(400, "malformed request line");
  }
  parse.head.method = std::string(parts[0]);
  if (!ParseTarget(parts[1], &parse.head)) return Refuse(400, "malformed request target");
  return parse;
}

// Saturating decimal: a byte position past what 64 bits hold is simply past any body.
bool ParsePosition(absl::string_view digits, uint64_t* value) {
  if (digits.empty()) return false;
  uint64_t v = 0;
  for (const char c : digits) {
    if (c < '0' || c > '9') return false;
    const uint64_t d = static_cast<uint64_t>(c - '0');
    v = v > (std::numeric_limits<uint64_t>::max() - d) / 10 ? std::numeric_limits<uint64_t>::max()
                                                            : v * 10 + d;
  }
  *value = v;
  return true;
}

}  // namespace

const std::string* HttpRequestHead::Header(absl::string_view name) const {
  for (const auto& [n, v] : headers) {
    if (n == name) return &v;
  }
  return nullptr;
}

bool PercentDecode(absl::string_view in, bool plus_is_space, std::string* out) {
  out->clear();
  out->reserve(in.size());
  for (size_t i = 0; i < in.size(); ++i) {
    char c = in[i];
    if (c == '%') {
      const int hi = i + 1 < in.size() ? HexValue(in[i + 1]) : -1;
      const int lo = i + 2 < in.size() ? HexValue(in[i + 2]) : -1;
      if (hi < 0 || lo < 0) return false;
      c = static_cast<char>(hi * 16 + lo);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      c = ' ';
    }
    if (c == '\0') return false;
    out->push_back(c);
  }
  return true;
}

HttpHeadParse ParseRequestHead(absl::string_view bytes, const HttpHeadLimits& limits) {
  // The head ends at the first empty line.
  size_t end = absl::string_view::npos;
  size_t lines = 0;
  for (size_t at = 0; at < bytes.size();) {
    const size_t nl = bytes.find('\n', at);
    if (nl == absl::string_view::npos) break;
    if (WithoutCr(bytes.substr(at, nl - at)).empty()) {
      // RFC 9112 §2.2: empty lines before the request line are ignored, not the end.
      if (lines > 0) {
        end = nl + 1;
        break;
      }
    } else {
      ++lines;
    }
    at = nl + 1;
  }
  const size_t first_nl = bytes.find('\n');
  if (end == absl::string_view::npos) {
    // Incomplete: refuse as soon as the limits are certain to be broken.
    if (first_nl == absl::string_view::npos && bytes.size() > limits.max_head_bytes) {
      return Refuse(414, "request line too long");
    }
    if (bytes.size() > limits.max_head_bytes) return Refuse(431, "request head too large");
    if (lines > static_cast<size_t>(limits.max_headers) + 1) {
      return Refuse(431, "too many header fields");
    }
    return HttpHeadParse{};
  }
  if (end > limits.max_head_bytes) {
    return first_nl + 1 > limits.max_head_bytes ? Refuse(414, "request line too long")
                                                : Refuse(431, "request head too large");
  }
  if (lines > static_cast<size_t>(limits.max_headers) + 1) {
    return Refuse(431, "too many header fields");
  }

  HttpHeadParse parse;
  bool request_line_seen = false;
  bool close = false;
  for (size_t at = 0; at < end;) {
    const size_t nl = bytes.find('\n', at);
    const absl::string_view line = WithoutCr(bytes.substr(at, nl - at));
    at = nl + 1;
    if (line.empty()) {
      if (request_line_seen) break;
      continue;
    }
    if (!request_line_seen) {
      parse = ParseRequestLine(line, std::move(parse));
      if (parse.outcome == HttpHeadParse::Outcome::kRefused) return parse;
      request_line_seen = true;
      continue;
    }
    // RFC 9112 §5.2: obsolete line folding is refused, not unfolded.
    if (line[0] == ' ' || line[0] == '\t') return Refuse(400, "folded header line");
    const size_t colon = line.find(':');
    if (colon == absl::string_view::npos || !IsToken(line.substr(0, colon))) {
      return Refuse(400, "malformed header line");
    }
    const absl::string_view value = absl::StripAsciiWhitespace(line.substr(colon + 1));
    if (!IsFieldValue(value)) return Refuse(400, "control character in a header value");
    std::string name = absl::AsciiStrToLower(line.substr(0, colon));
    if (name == "transfer-encoding") return Refuse(413, "request bodies are not accepted");
    if (name == "content-length") {
      uint64_t length = 0;
      if (!ParsePosition(value, &length)) return Refuse(400, "malformed Content-Length");
      if (length > 0) return Refuse(413, "request bodies are not accepted");
    }
    if (name == "connection") {
      for (absl::string_view option : absl::StrSplit(value, ',')) {
        option = absl::StripAsciiWhitespace(option);
        if (absl::EqualsIgnoreCase(option, "close")) close = true;
      }
    }
    parse.head.headers.emplace_back(std::move(name), std::string(value));
  }
  // HTTP/1.0's keep-alive is an old extension that clients get wrong: one request each.
  parse.head.keep_alive = parse.head.minor_version == 1 && !close;
  parse.outcome = HttpHeadParse::Outcome::kComplete;
  parse.head_bytes = end;
  return parse;
}

ByteRange ParseByteRange(absl::string_view header, uint64_t size) {
  ByteRange whole;
  const absl::string_view h = absl::StripAsciiWhitespace(header);
  const size_t eq = h.find('=');
  if (eq == absl::string_view::npos ||
      !absl::EqualsIgnoreCase(absl::StripAsciiWhitespace(h.substr(0, eq)), "bytes")) {
    return whole;
  }
  bool any_spec = false, any_satisfiable = false;
  uint64_t first = std::numeric_limits<uint64_t>::max(), last = 0;
  for (absl::string_view spec : absl::StrSplit(h.substr(eq + 1), ',')) {
    spec = absl::StripAsciiWhitespace(spec);
    if (spec.empty()) continue;  // RFC 9110's list syntax allows empty elements
    const size_t dash = spec.find('-');
    if (dash == absl::string_view::npos) return whole;
    const absl::string_view a = spec.substr(0, dash), b = spec.substr(dash + 1);
    uint64_t from = 0, to = 0;
    if (a.empty()) {  // suffix: the last `to` bytes
      if (!ParsePosition(b, &to)) return whole;
      any_spec = true;
      if (to == 0 || size == 0) continue;
      from = size - std::min(to, size);
      to = size - 1;
    } else {
      if (!ParsePosition(a, &from)) return whole;
      if (b.empty()) {
        to = std::numeric_limits<uint64_t>::max();
      } else if (!ParsePosition(b, &to) || to < from) {
        return whole;
      }
      any_spec = true;
      if (from >= size) continue;
      to = std::min(to, size - 1);
    }
    any_satisfiable = true;
    first = std::min(first, from);
    last = std::max(last, to);
  }
  if (!any_spec) return whole;
  if (!any_satisfiable) return ByteRange{ByteRange::Kind::kUnsatisfiable, 0, 0};
  return ByteRange{ByteRange::Kind::kPart, first, last};
}

const char* HttpReasonPhrase(int status) {
  switch (status) {
    case 200: return "OK";
    case 206: return "Partial Content";
    case 400: return "Bad Request";
    case 401: return "Unauthorized";
    case 403: return "Forbidden";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 408: return "Request Timeout";
    case 413: return "Content Too Large";
    case 414: return "URI Too Long";
    case 416: return "Range Not Satisfiable";
    case 431: return "Request Header Fields Too Large";
    case 500: return "Internal Server Error";
    case 503: return "Service Unavailable";
    case 504: return "Gateway Timeout";
    case 505: return "HTTP Version Not Supported";
    default: return "Unknown";
  }
}

}  // namespace plx::web

// The side HTTP server's request parser (web/http_request.h): what any client of plenoxd's
// metrics and viewer port can send. The input is the bytes a connection receives; the head is
// parsed under tight limits and under the defaults, and its Range header (or the input's first
// line, as a header value) is resolved against bodies of several sizes. Checked: a complete
// head lies inside the input and within the limits, a refusal carries a 4xx/5xx status and a
// reason, and a range is always inside its body.
#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/strings/string_view.h"
#include "fuzz/fuzz_util.h"
#include "web/http_request.h"

namespace {

void CheckHead(absl::string_view bytes, const plx::web::HttpHeadLimits& limits) {
  using Outcome = plx::web::HttpHeadParse::Outcome;
  const plx::web::HttpHeadParse p = plx::web::ParseRequestHead(bytes, limits);
  if (p.outcome == Outcome::kRefused) {
    PLX_FUZZ_CHECK(p.status >= 400 && p.status < 600, "refusal without an error status");
    PLX_FUZZ_CHECK(!p.reason.empty(), "refusal without a reason");
    return;
  }
  if (p.outcome == Outcome::kNeedMore) {
    PLX_FUZZ_CHECK(bytes.size() <= limits.max_head_bytes, "waited past the head limit");
    return;
  }
  PLX_FUZZ_CHECK(p.head_bytes > 0 && p.head_bytes <= bytes.size(), "head outside the input");
  PLX_FUZZ_CHECK(p.head_bytes <= limits.max_head_bytes, "head past the byte limit");
  PLX_FUZZ_CHECK(p.head.headers.size() <= static_cast<size_t>(limits.max_headers),
                 "more headers than allowed");
  PLX_FUZZ_CHECK(!p.head.path.empty() && p.head.path[0] == '/', "path not origin-form");
  PLX_FUZZ_CHECK(p.head.path.find('\0') == std::string::npos, "NUL in the path");
  if (const std::string* range = p.head.Header("range")) {
    for (const uint64_t size : {uint64_t{0}, uint64_t{1}, uint64_t{850573}}) {
      plx::web::ParseByteRange(*range, size);
    }
  }
}

void CheckRange(absl::string_view header) {
  for (const uint64_t size : {uint64_t{0}, uint64_t{1}, uint64_t{100}, ~uint64_t{0}}) {
    const plx::web::ByteRange r = plx::web::ParseByteRange(header, size);
    if (r.kind == plx::web::ByteRange::Kind::kPart) {
      PLX_FUZZ_CHECK(r.first <= r.last && r.last < size, "range outside its body");
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  plx::web::HttpHeadLimits tight;
  tight.max_head_bytes = 256;
  tight.max_headers = 4;
  CheckHead(bytes, tight);
  CheckHead(bytes, plx::web::HttpHeadLimits{});
  CheckRange(bytes.substr(0, bytes.find('\n')));
  return 0;
}

// Structured logs: one logfmt line per event on stderr ("ts=... level=info event=rpc ...").
#pragma once

#include <cstddef>
#include <string>
#include <utility>

#include "absl/types/span.h"

namespace plx::server {

// `fields`: key = value pairs, in order (a braced list works). Values are escaped (no control
// characters, NUL or non-ASCII bytes: \xNN) and capped, since many come from clients: names and
// ids at kMaxLogNameChars, the free-text keys "message", "error", "reason", "devices" and
// "file" at kMaxLogTextChars; a cut value ends in "…".
inline constexpr size_t kMaxLogNameChars = 128;
inline constexpr size_t kMaxLogTextChars = 1024;
using LogField = std::pair<const char*, std::string>;
void LogEvent(const char* level, const std::string& event,
              absl::Span<const LogField> fields = {});

}  // namespace plx::server

// Structured logs: one logfmt line per event on stderr ("ts=... level=info event=rpc ...").
#pragma once

#include <string>
#include <utility>

#include "absl/types/span.h"

namespace plx::server {

// `fields`: key = value pairs, in order (a braced list works).
using LogField = std::pair<const char*, std::string>;
void LogEvent(const char* level, const std::string& event,
              absl::Span<const LogField> fields = {});

}  // namespace plx::server

// Structured logs: one logfmt line per event on stderr ("ts=... level=info event=rpc ...").
#pragma once

#include <initializer_list>
#include <string>
#include <utility>

namespace plx::server {

void LogEvent(const char* level, const std::string& event,
              std::initializer_list<std::pair<const char*, std::string>> fields = {});

}  // namespace plx::server

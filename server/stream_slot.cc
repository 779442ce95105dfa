#include "server/stream_slot.h"

#include <cstdint>

#include "absl/strings/str_cat.h"

namespace plx::server {

absl::Status StreamSlot::Acquire(DaemonState& state, const grpc::CallbackServerContext* context) {
  if (absl::Status s = CheckCall(state, context); !s.ok()) return s;
  const int64_t now = state.metrics->active_streams.fetch_add(1) + 1;
  if (now > state.config.max_streams) {
    state.metrics->active_streams.fetch_sub(1);
    return absl::ResourceExhaustedError(
        absl::StrCat("too many open streams (limit ", state.config.max_streams, "); retry later"));
  }
  state_ = &state;
  return absl::OkStatus();
}

void StreamSlot::Release() {
  if (state_ == nullptr) return;
  state_->metrics->active_streams.fetch_sub(1);
  state_ = nullptr;
}

}  // namespace plx::server

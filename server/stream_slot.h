// One of the daemon's --max-streams slots, held by a streaming call (Track, Integrate, Slam,
// Export, WatchJob) from its admission until its reactor is done. Every stream is admitted the
// same way (drain, auth, then the limit) and gives its slot back exactly once, whichever way it
// ends: the slot releases itself when the reactor is deleted.
#pragma once

#include <grpcpp/server_context.h>

#include "absl/status/status.h"
#include "server/daemon_state.h"

namespace plx::server {

class StreamSlot {
 public:
  StreamSlot() = default;
  ~StreamSlot() { Release(); }
  StreamSlot(const StreamSlot&) = delete;
  StreamSlot& operator=(const StreamSlot&) = delete;

  // CheckCall, then the concurrent-stream limit: RESOURCE_EXHAUSTED when `state` already has
  // config.max_streams open. On OK this holds a slot (metrics->active_streams counts it) until
  // Release. Call at most once.
  absl::Status Acquire(DaemonState& state, const grpc::CallbackServerContext* context);
  // Gives the slot back, if held; later calls do nothing.
  void Release();
  bool held() const { return state_ != nullptr; }

 private:
  DaemonState* state_ = nullptr;  // while held
};

}  // namespace plx::server

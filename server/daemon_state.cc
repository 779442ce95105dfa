#include "server/daemon_state.h"

#include "absl/time/clock.h"
#include "absl/time/time.h"

namespace plx::server {
namespace {

// Compares without an early exit, so the time taken does not reveal how much of a guess matched.
bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t i = 0; i < a.size(); ++i) diff |= a[i] ^ (i < b.size() ? b[i] : 0);
  return diff == 0;
}

}  // namespace

absl::Status CheckCall(const DaemonState& state, const grpc::CallbackServerContext* context) {
  if (state.draining.load()) {
    return absl::UnavailableError("plenoxd is shutting down; retry on another instance");
  }
  if (state.config.auth_token.empty()) return absl::OkStatus();
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return absl::UnauthenticatedError(
        "missing credentials: send metadata \"authorization: Bearer <token>\"");
  }
  const std::string value(it->second.data(), it->second.size());
  if (!ConstantTimeEquals(value, "Bearer " + state.config.auth_token)) {
    return absl::UnauthenticatedError("invalid bearer token");
  }
  return absl::OkStatus();
}

absl::Status CancelledCallStatus(const DaemonState& state,
                                 const grpc::CallbackServerContext* context,
                                 const char* otherwise) {
  // gRPC cancels the calls left at the drain's deadline, never before it; the margin covers
  // the clocks' rounding.
  const absl::Time now = absl::Now();
  if (state.draining.load() &&
      now >= absl::FromUnixNanos(state.drain_deadline_ns.load()) - absl::Milliseconds(10)) {
    return absl::CancelledError(
        "cancelled: plenoxd is shutting down (the drain's grace period ended)");
  }
  if (absl::FromChrono(context->deadline()) <= now) {
    return absl::CancelledError("cancelled: the call's deadline passed");
  }
  return absl::CancelledError(otherwise);
}

absl::Status QueuedCallStatus(bool worker_stopped, const grpc::CallbackServerContext* context) {
  if (worker_stopped) return absl::UnavailableError("plenoxd is shutting down");
  if (context->IsCancelled()) {
    return absl::CancelledError("the call was cancelled before its work started");
  }
  return absl::OkStatus();
}

}  // namespace plx::server

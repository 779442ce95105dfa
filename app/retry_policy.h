// When and how long a client waits before it calls a daemon again after the daemon went away
// (issue 24, "clients ride through a failover"): exponential backoff with jitter under an
// overall deadline, and which failures may be retried at all. Plain C++ on absl::Status, no
// gRPC, so the CLI's calls and streams (clients/plenox/remote_client.h, remote_slam.cc) share
// one policy, and a test drives it with a fake clock. The Python client has the same policy
// (clients/python/plenoxd_client/retry.py).
#pragma once

#include <cstdint>
#include <functional>
#include <random>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"

namespace plx {

struct RetryOptions {
  // Overall deadline of one outage, from its first failure: after it the failure is reported.
  // Zero: no retries. It bounds the waiting, not a call already running (calls keep their own
  // deadlines). 30 s covers a daemon restarted in place (a few seconds) and a failover to
  // another replica with a 100 MB map to load (the goal: 10 s), with room to spare.
  absl::Duration budget = absl::Seconds(30);
  // The first wait, then multiplied by `multiplier` after each failed attempt up to
  // `max_backoff`: 0.1, 0.2, 0.4, 0.8, 1.6, 2, 2, ... s. A restarted daemon is found within
  // about max_backoff of being back, and a client that is waiting costs the daemon (or the
  // proxy in front of a fleet) one connection attempt every max_backoff.
  absl::Duration initial_backoff = absl::Milliseconds(100);
  double multiplier = 2.0;
  absl::Duration max_backoff = absl::Seconds(2);
  // Each wait is the nominal one times a factor drawn uniformly from [1 - jitter, 1 + jitter]
  // (gRPC's own reconnection backoff uses 0.2): the clients of a daemon that died all lost it
  // at the same moment, and without jitter they would come back to its replacement together,
  // attempt after attempt.
  double jitter = 0.2;
};

// InvalidArgument naming `flag` for a budget that is negative or not finite, or backoff
// settings that would not back off (initial_backoff <= 0, multiplier < 1, max_backoff <
// initial_backoff, jitter outside [0, 1)).
absl::Status ValidateRetryOptions(const RetryOptions& options,
                                  const std::string& flag = "--retry-seconds");

// Whether a failed call may be made again. Only UNAVAILABLE: the daemon was not there (the
// connection refused or lost, a daemon draining on SIGTERM, which says "retry on another
// instance"), so another attempt can find its replacement. And only for calls that are safe
// to repeat (`idempotent`): a call that changes something may have been done before the
// connection was lost, so repeating it would do it twice or fail on its own first success
// (CreateMap's ALREADY_EXISTS); reads, SaveMap (writes the same file again) and LoadMap (reads
// it again) are idempotent. Never retried: DEADLINE_EXCEEDED (the call may still be running
// on the daemon, and its time is spent), RESOURCE_EXHAUSTED (a limit: the same call is refused
// again), CANCELLED (the user's), INTERNAL / UNKNOWN (a bug that a retry would hide), and the
// caller's own errors (INVALID_ARGUMENT, NOT_FOUND, UNAUTHENTICATED, ...).
bool IsRetryable(const absl::Status& status, bool idempotent);

// Time for the backoff: the real clock, or a test's fake one.
class RetryClock {
 public:
  virtual ~RetryClock() = default;
  virtual absl::Time Now() = 0;
  virtual void SleepFor(absl::Duration duration) = 0;
  // The process's clock (absl::Now, absl::SleepFor).
  static RetryClock& Real();
};

// The waits of one outage. Start() at its first failure; then each Wait() sleeps before the
// next attempt, and says false (without sleeping) once the budget is spent. The last wait is
// cut short to end at the deadline, so the last attempt is made at the deadline, not before
// it. Not thread-safe.
class Backoff {
 public:
  // `seed`: the jitter's random numbers (tests pass a fixed one).
  Backoff(const RetryOptions& options, RetryClock& clock, uint64_t seed = std::random_device{}());

  void Start();
  bool Wait();

  // Whether the deadline has passed (Wait() would say false).
  bool spent() const { return clock_.Now() >= deadline_; }
  int waits() const { return waits_; }
  // Since Start().
  absl::Duration elapsed() const { return clock_.Now() - started_; }
  // The nominal wait before the next attempt, without jitter.
  absl::Duration next_nominal() const { return nominal_; }

 private:
  RetryOptions options_;
  RetryClock& clock_;
  std::mt19937_64 random_;
  absl::Time started_;
  absl::Time deadline_;
  absl::Duration nominal_;
  int waits_ = 0;
};

// Calls `call` until it returns a status that IsRetryable(status, idempotent) refuses, or the
// budget of `options` is spent; `on_wait` (may be empty) is told about each wait before it
// (the failure, the attempt that failed, 1-based) so a command can say that it is waiting.
// Returns the last attempt's status.
absl::Status CallWithRetry(
    const RetryOptions& options, bool idempotent, const std::function<absl::Status()>& call,
    RetryClock& clock = RetryClock::Real(),
    const std::function<void(const absl::Status&, int attempt)>& on_wait = {});

// The same for a call with a result.
template <typename T>
absl::StatusOr<T> CallWithRetry(
    const RetryOptions& options, bool idempotent, const std::function<absl::StatusOr<T>()>& call,
    RetryClock& clock = RetryClock::Real(),
    const std::function<void(const absl::Status&, int attempt)>& on_wait = {}) {
  absl::StatusOr<T> result = absl::UnknownError("not called");
  const absl::Status last = CallWithRetry(
      options, idempotent,
      [&]() -> absl::Status {
        result = call();
        return result.status();
      },
      clock, on_wait);
  if (!last.ok()) return last;
  return result;
}

}  // namespace plx

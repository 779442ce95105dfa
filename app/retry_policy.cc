#include "app/retry_policy.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"

namespace plx {
namespace {

class RealClock final : public RetryClock {
 public:
  absl::Time Now() override { return absl::Now(); }
  void SleepFor(absl::Duration duration) override { absl::SleepFor(duration); }
};

}  // namespace

RetryClock& RetryClock::Real() {
  static RealClock* clock = new RealClock();
  return *clock;
}

absl::Status ValidateRetryOptions(const RetryOptions& o, const std::string& flag) {
  if (o.budget < absl::ZeroDuration() || o.budget == absl::InfiniteDuration()) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, " must be a finite number of seconds >= 0 (0: no retries)"));
  }
  if (o.initial_backoff <= absl::ZeroDuration() || !(o.multiplier >= 1.0) ||
      !std::isfinite(o.multiplier) || o.max_backoff < o.initial_backoff ||
      o.max_backoff == absl::InfiniteDuration() || !(o.jitter >= 0.0 && o.jitter < 1.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        flag, ": the backoff must grow from a positive first wait to a finite largest one, "
              "with jitter in [0, 1)"));
  }
  return absl::OkStatus();
}

bool IsRetryable(const absl::Status& status, bool idempotent) {
  return idempotent && status.code() == absl::StatusCode::kUnavailable;
}

Backoff::Backoff(const RetryOptions& options, RetryClock& clock, uint64_t seed)
    : options_(options), clock_(clock), random_(seed) {
  Start();
}

void Backoff::Start() {
  started_ = clock_.Now();
  deadline_ = started_ + options_.budget;
  nominal_ = options_.initial_backoff;
  waits_ = 0;
}

bool Backoff::Wait() {
  const absl::Time now = clock_.Now();
  if (now >= deadline_) return false;
  std::uniform_real_distribution<double> factor(1.0 - options_.jitter, 1.0 + options_.jitter);
  const absl::Duration wait = std::min(nominal_ * factor(random_), deadline_ - now);
  nominal_ = std::min(nominal_ * options_.multiplier, options_.max_backoff);
  ++waits_;
  clock_.SleepFor(wait);
  return true;
}

absl::Status CallWithRetry(const RetryOptions& options, bool idempotent,
                           const std::function<absl::Status()>& call, RetryClock& clock,
                           const std::function<void(const absl::Status&, int)>& on_wait) {
  absl::Status status = call();
  if (!IsRetryable(status, idempotent)) return status;
  Backoff backoff(options, clock);
  for (int attempt = 1;; ++attempt) {
    if (backoff.spent()) return status;
    if (on_wait) on_wait(status, attempt);
    backoff.Wait();
    status = call();
    if (!IsRetryable(status, idempotent)) return status;
  }
}

}  // namespace plx

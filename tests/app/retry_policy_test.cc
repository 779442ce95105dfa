#include "app/retry_policy.h"

#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

// Time stands still except when the code under test sleeps (or a call takes time, `Advance`);
// every sleep is recorded.
class FakeClock final : public RetryClock {
 public:
  absl::Time Now() override { return now_; }
  void SleepFor(absl::Duration d) override {
    sleeps.push_back(d);
    now_ += d;
  }
  void Advance(absl::Duration d) { now_ += d; }
  absl::Duration slept() const {
    absl::Duration total;
    for (absl::Duration d : sleeps) total += d;
    return total;
  }

  std::vector<absl::Duration> sleeps;

 private:
  absl::Time now_ = absl::FromUnixSeconds(1000);
};

TEST(RetryPolicyTest, OnlyUnavailableOfAnIdempotentCallIsRetried) {
  EXPECT_TRUE(IsRetryable(absl::UnavailableError("connection refused"), true));
  EXPECT_FALSE(IsRetryable(absl::UnavailableError("connection refused"), false));
  for (const absl::Status& s :
       {absl::OkStatus(), absl::DeadlineExceededError("slow"), absl::ResourceExhaustedError("x"),
        absl::CancelledError("x"), absl::InternalError("x"), absl::UnknownError("x"),
        absl::InvalidArgumentError("x"), absl::NotFoundError("x"),
        absl::UnauthenticatedError("x"), absl::AbortedError("x")}) {
    EXPECT_FALSE(IsRetryable(s, true)) << s;
  }
}

TEST(RetryPolicyTest, WaitsGrowExponentiallyWithinTheJitterUpToTheLargest) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::Seconds(30);
  Backoff backoff(o, clock, /*seed=*/7);
  const double nominal_ms[] = {100, 200, 400, 800, 1600, 2000, 2000, 2000};
  for (double ms : nominal_ms) {
    EXPECT_EQ(backoff.next_nominal(), absl::Milliseconds(ms));
    ASSERT_TRUE(backoff.Wait());
    const double waited = absl::ToDoubleMilliseconds(clock.sleeps.back());
    EXPECT_GE(waited, 0.8 * ms);
    EXPECT_LE(waited, 1.2 * ms);
  }
  EXPECT_EQ(backoff.waits(), 8);
}

TEST(RetryPolicyTest, JitterSpreadsClientsThatFailedTogether) {
  // Two clients that lost the daemon at the same moment do not come back in step.
  FakeClock a, b;
  RetryOptions o;
  Backoff first(o, a, /*seed=*/1), second(o, b, /*seed=*/2);
  int different = 0;
  for (int i = 0; i < 6; ++i) {
    ASSERT_TRUE(first.Wait());
    ASSERT_TRUE(second.Wait());
    different += a.sleeps.back() != b.sleeps.back();
  }
  EXPECT_EQ(different, 6);
  // And without jitter every wait is the nominal one.
  FakeClock c;
  o.jitter = 0.0;
  Backoff exact(o, c);
  ASSERT_TRUE(exact.Wait());
  ASSERT_TRUE(exact.Wait());
  EXPECT_EQ(c.sleeps[0], absl::Milliseconds(100));
  EXPECT_EQ(c.sleeps[1], absl::Milliseconds(200));
}

TEST(RetryPolicyTest, TheLastWaitEndsAtTheDeadlineAndNothingWaitsPastIt) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::Seconds(3);
  o.jitter = 0.0;
  Backoff backoff(o, clock);
  while (backoff.Wait()) {
  }
  // 0.1 + 0.2 + 0.4 + 0.8 = 1.5 s, then 1.5 s of the 1.6 s wait: the deadline exactly.
  EXPECT_EQ(clock.slept(), absl::Seconds(3));
  ASSERT_EQ(clock.sleeps.size(), 5u);
  EXPECT_EQ(clock.sleeps.back(), absl::Milliseconds(1500));
  EXPECT_TRUE(backoff.spent());
  EXPECT_FALSE(backoff.Wait());
  EXPECT_EQ(clock.sleeps.size(), 5u) << "no sleep once the budget is spent";
  // Time spent in the calls counts against the budget too.
  FakeClock slow;
  Backoff second(o, slow);
  slow.Advance(absl::Seconds(2.95));
  ASSERT_TRUE(second.Wait());
  EXPECT_EQ(slow.sleeps.back(), absl::Milliseconds(50));
  EXPECT_FALSE(second.Wait());
}

TEST(RetryPolicyTest, StartBeginsANewOutageWithAFreshBudget) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::Seconds(1);
  Backoff backoff(o, clock);
  while (backoff.Wait()) {
  }
  clock.Advance(absl::Minutes(5));  // the daemon came back and served for a while
  backoff.Start();
  EXPECT_FALSE(backoff.spent());
  EXPECT_EQ(backoff.next_nominal(), absl::Milliseconds(100));
  EXPECT_TRUE(backoff.Wait());
  EXPECT_EQ(backoff.waits(), 1);
}

TEST(RetryPolicyTest, AZeroBudgetNeverRetries) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::ZeroDuration();
  int calls = 0;
  const absl::Status s = CallWithRetry(
      o, true,
      [&] {
        ++calls;
        return absl::UnavailableError("down");
      },
      clock);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(calls, 1);
  EXPECT_TRUE(clock.sleeps.empty());
}

TEST(RetryPolicyTest, CallWithRetryRidesThroughAnOutageAndReportsEachWait) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::Seconds(10);
  // The daemon is back 1.2 s after the first failure.
  const absl::Time back = clock.Now() + absl::Seconds(1.2);
  std::vector<int> told;
  int calls = 0;
  const absl::StatusOr<int> r = CallWithRetry<int>(
      o, true,
      [&]() -> absl::StatusOr<int> {
        ++calls;
        if (clock.Now() < back) return absl::UnavailableError("connection refused");
        return 42;
      },
      clock, [&](const absl::Status& s, int attempt) {
        EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
        told.push_back(attempt);
      });
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(*r, 42);
  EXPECT_EQ(calls, static_cast<int>(told.size()) + 1);
  for (size_t i = 0; i < told.size(); ++i) EXPECT_EQ(told[i], static_cast<int>(i) + 1);
  // Found within one wait of being back: by then the waits are at most 1.6 s nominal (0.1 +
  // 0.2 + 0.4 + 0.8 = 1.5 s nominal reach 1.2 s unless every jitter factor is the lowest).
  EXPECT_GE(clock.slept(), absl::Seconds(1.2));
  EXPECT_LE(clock.slept(), absl::Seconds(1.2) + 1.2 * absl::Milliseconds(1600));
}

TEST(RetryPolicyTest, CallWithRetryGivesUpAtTheDeadlineWithTheLastFailure) {
  FakeClock clock;
  RetryOptions o;
  o.budget = absl::Seconds(5);
  int calls = 0;
  const absl::Status s = CallWithRetry(
      o, true,
      [&] {
        ++calls;
        return absl::UnavailableError(std::to_string(calls));
      },
      clock);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(s.message(), std::to_string(calls)) << "the last attempt's failure";
  EXPECT_EQ(clock.slept(), absl::Seconds(5));
  EXPECT_GE(calls, 5);
}

TEST(RetryPolicyTest, OtherFailuresAndNonIdempotentCallsAreNotRetried) {
  FakeClock clock;
  RetryOptions o;
  int calls = 0;
  EXPECT_EQ(CallWithRetry(
                o, true,
                [&] {
                  ++calls;
                  return absl::DeadlineExceededError("slow");
                },
                clock)
                .code(),
            absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(CallWithRetry(
                o, false,
                [&] {
                  ++calls;
                  return absl::UnavailableError("lost after it was sent");
                },
                clock)
                .code(),
            absl::StatusCode::kUnavailable);
  EXPECT_EQ(calls, 2);
  EXPECT_TRUE(clock.sleeps.empty());
}

TEST(RetryPolicyTest, BadOptionsAreRefusedNamingTheFlag) {
  RetryOptions o;
  EXPECT_TRUE(ValidateRetryOptions(o).ok());
  o.budget = absl::Seconds(-1);
  EXPECT_THAT(ValidateRetryOptions(o).message(), HasSubstr("--retry-seconds"));
  o.budget = absl::InfiniteDuration();
  EXPECT_FALSE(ValidateRetryOptions(o).ok());
  o = RetryOptions();
  o.multiplier = 0.5;
  EXPECT_FALSE(ValidateRetryOptions(o, "retry").ok());
  o = RetryOptions();
  o.jitter = 1.0;
  EXPECT_FALSE(ValidateRetryOptions(o).ok());
  o = RetryOptions();
  o.initial_backoff = absl::ZeroDuration();
  EXPECT_FALSE(ValidateRetryOptions(o).ok());
}

}  // namespace
}  // namespace plx

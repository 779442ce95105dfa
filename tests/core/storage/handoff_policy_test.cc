// The handoff rule of shared map storage (core/storage/lease_policy.h, "Handoff") on a fake
// clock: a daemon asked for a map another holds records a request; the holder keeps its token
// and the request through renewals, gives the map up only once it is idle, and the released
// lease is reserved for the requester until the request lapses. Then the same through a
// directory (TakeOrRequestLease on DirectoryMapStorage), where the request is stored in the
// lease record.
#include <filesystem>
#include <fstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/storage/directory_storage.h"
#include "core/storage/lease_policy.h"
#include "core/storage/map_storage.h"
#include "tests/test_util.h"

namespace plx {
namespace handoff_policy_test {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;

const absl::Time kT0 = absl::FromUnixSeconds(1000000);
// Renewed every 4 s; handoffs after 4 s without calls; requests last 12 s.
const LeaseTerms kTerms = LeaseTermsFor(absl::Seconds(12));

absl::Time At(double seconds) { return kT0 + absl::Seconds(seconds); }

LeaseRecord HeldByA() { return *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms); }

TEST(HandoffPolicyTest, TermsFollowTheLeaseLength) {
  EXPECT_EQ(kTerms.handoff_quiet, absl::Seconds(4));
  EXPECT_EQ(kTerms.handoff_wait, absl::Seconds(12));
}

TEST(HandoffPolicyTest, ARequestAgainstALiveHolderIsRecordedAndSurvivesItsRenewals) {
  const LeaseRecord a = HeldByA();
  absl::StatusOr<LeaseRecord> asked = RequestHandoff("m", a, "B", At(1), kTerms);
  ASSERT_TRUE(asked.ok()) << asked.status();
  EXPECT_EQ(asked->wanted_by, "B");
  EXPECT_EQ(asked->wanted_until, At(13));
  EXPECT_EQ(asked->holder, "A");
  EXPECT_EQ(asked->token, a.token) << "a request changes nobody's generation";
  EXPECT_TRUE(HandoffPending(*asked, "A", At(2)));
  EXPECT_FALSE(HandoffPending(*asked, "B", At(2))) << "one's own request is not pending for it";
  EXPECT_FALSE(HandoffPending(*asked, "A", At(13))) << "lapsed";
  // The holder may still write and renew; the renewal keeps the request.
  EXPECT_TRUE(CheckFence("m", *asked, "A", a.token, At(2), kTerms).ok());
  absl::StatusOr<LeaseRecord> renewed = NextLease("m", *asked, "A", a.token, At(4), kTerms);
  ASSERT_TRUE(renewed.ok()) << renewed.status();
  EXPECT_EQ(renewed->wanted_by, "B");
  // A newer request (another router view) replaces it.
  absl::StatusOr<LeaseRecord> c = RequestHandoff("m", *renewed, "C", At(5), kTerms);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->wanted_by, "C");
  EXPECT_EQ(c->wanted_until, At(17));
}

TEST(HandoffPolicyTest, NoRequestForAFreeLeaseOrOnesOwn) {
  const LeaseRecord a = HeldByA();
  EXPECT_EQ(RequestHandoff("m", a, "A", At(1), kTerms).status().code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(RequestHandoff("m", LeaseRecord{}, "B", At(1), kTerms).status().code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(RequestHandoff("m", a, "B", At(12), kTerms).status().code(),
            absl::StatusCode::kFailedPrecondition)
      << "expired: B takes it instead";
}

TEST(HandoffPolicyTest, AReleasedLeaseIsReservedForTheRequesterUntilTheRequestLapses) {
  const LeaseRecord asked = *RequestHandoff("m", HeldByA(), "B", At(1), kTerms);
  const LeaseRecord released = ReleasedLease(asked);
  EXPECT_EQ(released.wanted_by, "B");
  // The old holder (a stray call) and a third daemon are refused: the map is moving to B.
  for (const char* other : {"A", "C"}) {
    absl::StatusOr<LeaseRecord> refused = NextLease("m", released, other, 0, At(2), kTerms);
    ASSERT_FALSE(refused.ok()) << other;
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnavailable) << other;
    EXPECT_THAT(refused.status().message(), AllOf(HasSubstr("moving to daemon B"),
                                                  HasSubstr("11.0 s more")));
    EXPECT_EQ(RequestHandoff("m", released, other, At(2), kTerms).status().code(),
              absl::StatusCode::kUnavailable)
        << "a reservation is not overwritten";
  }
  absl::StatusOr<LeaseRecord> b = NextLease("m", released, "B", 0, At(2), kTerms);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->token, 2u);
  EXPECT_TRUE(b->wanted_by.empty()) << "a take clears the request";
  // A requester that died: after the request lapses anyone takes the lease.
  absl::StatusOr<LeaseRecord> c = NextLease("m", released, "C", 0, At(13), kTerms);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->token, 2u);
}

TEST(HandoffPolicyTest, AHolderGivesUpOnlyWhenIdleAndNotMapping) {
  EXPECT_FALSE(ShouldHandOff(/*mapping=*/true, At(0), At(100), kTerms));
  EXPECT_FALSE(ShouldHandOff(false, At(10), At(13.9), kTerms)) << "called 3.9 s ago";
  EXPECT_TRUE(ShouldHandOff(false, At(10), At(14), kTerms));
  EXPECT_TRUE(ShouldHandOff(false, absl::InfinitePast(), At(0), kTerms)) << "never called";
}

TEST(HandoffPolicyTest, TheRequestersErrorIsRetryableAndNamesTheHolder) {
  const absl::Status error = HandoffRequestedError("m", HeldByA(), kTerms);
  EXPECT_EQ(error.code(), absl::StatusCode::kUnavailable);
  EXPECT_TRUE(IsHandoffRequested(error));
  EXPECT_FALSE(IsHandoffRequested(absl::UnavailableError("volume unreachable")));
  EXPECT_THAT(error.message(), AllOf(HasSubstr("owned by another daemon"),
                                     HasSubstr("generation 1"), HasSubstr("holder A"),
                                     HasSubstr("4.0 s"), HasSubstr("retry")));
}

class HandoffStorageTest : public ::testing::Test {
 protected:
  ~HandoffStorageTest() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::function<absl::Time()> Clock() {
    return [this] { return now_; };
  }

  const std::string dir_ = testing::MakeTempDir("plx_handoff_storage");
  DirectoryMapStorage a_{DirectoryStorageOptions{dir_, absl::Milliseconds(200), "A"}};
  DirectoryMapStorage b_{DirectoryStorageOptions{dir_, absl::Milliseconds(200), "B"}};
  absl::Time now_ = kT0;
};

TEST_F(HandoffStorageTest, TheRequestIsStoredInTheLeaseRecordAndTheRequesterTakesAfterRelease) {
  absl::StatusOr<LeaseRecord> a = TakeOrRequestLease(a_, "m", "A", Clock(), kTerms);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->token, 1u);
  EXPECT_TRUE(a->wanted_by.empty());
  now_ += absl::Seconds(1);
  absl::StatusOr<LeaseRecord> b = TakeOrRequestLease(b_, "m", "B", Clock(), kTerms);
  ASSERT_FALSE(b.ok());
  EXPECT_TRUE(IsHandoffRequested(b.status())) << b.status();
  // The holder reads it back (the text record round-trips the request).
  absl::StatusOr<LeaseRecord> seen = a_.ReadLease("m");
  ASSERT_TRUE(seen.ok()) << seen.status();
  EXPECT_EQ(seen->wanted_by, "B");
  EXPECT_EQ(seen->wanted_until, now_ + kTerms.handoff_wait);
  EXPECT_EQ(seen->holder, "A");
  // Renewed: still A's, still wanted by B.
  absl::StatusOr<LeaseRecord> renewed = AcquireLease(a_, "m", "A", a->token, Clock(), kTerms);
  ASSERT_TRUE(renewed.ok()) << renewed.status();
  EXPECT_EQ(renewed->wanted_by, "B");
  // A gives it up; A's stray call is refused, B takes it a generation higher.
  ASSERT_TRUE(ReleaseLease(a_, "m", "A", a->token).ok());
  absl::StatusOr<LeaseRecord> stray = TakeOrRequestLease(a_, "m", "A", Clock(), kTerms);
  EXPECT_EQ(stray.status().code(), absl::StatusCode::kUnavailable) << stray.status();
  EXPECT_FALSE(IsHandoffRequested(stray.status())) << "nothing was asked: the map is moving";
  EXPECT_EQ(a_.ReadLease("m")->wanted_by, "B");
  absl::StatusOr<LeaseRecord> taken = TakeOrRequestLease(b_, "m", "B", Clock(), kTerms);
  ASSERT_TRUE(taken.ok()) << taken.status();
  EXPECT_EQ(taken->token, 2u);
  EXPECT_EQ(taken->holder, "B");
  EXPECT_TRUE(a_.ReadLease("m")->wanted_by.empty());
}

TEST_F(HandoffStorageTest, RecordsWithoutARequestReadAsBefore) {
  std::ofstream(a_.LeasePath("m")) << "plenoxd-lease 1\nholder A\ntoken 3\n"
                                      "expires_unix_ns 5\nrevision 2\n";
  absl::StatusOr<LeaseRecord> r = a_.ReadLease("m");
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->token, 3u);
  EXPECT_TRUE(r->wanted_by.empty());
  std::ofstream(a_.LeasePath("n")) << "plenoxd-lease 1\nholder A\ntoken 3\n"
                                      "expires_unix_ns 5\nrevision 2\nwanted_by B\n"
                                      "wanted_until_unix_ns x\n";
  EXPECT_EQ(a_.ReadLease("n").status().code(), absl::StatusCode::kDataLoss);
}

}  // namespace handoff_policy_test
}  // namespace plx

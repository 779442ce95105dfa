// The lease rule of shared map storage (core/storage/lease_policy.h) on a fake clock: a free
// lease is taken with the next token, a live one of another holder is refused, a renewal
// keeps the token, a takeover raises it, and a holder whose token was superseded may neither
// renew nor write (it lost the map), however the clocks stand.
#include "core/storage/lease_policy.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

const absl::Time kT0 = absl::FromUnixSeconds(1000000);
const LeaseTerms kTerms = LeaseTermsFor(absl::Seconds(12));  // renew 4 s, write margin 3 s

absl::Time At(double seconds) { return kT0 + absl::Seconds(seconds); }

TEST(LeasePolicyTest, TermsFollowTheLeaseLength) {
  EXPECT_EQ(kTerms.term, absl::Seconds(12));
  EXPECT_EQ(kTerms.renew_every, absl::Seconds(4));
  EXPECT_EQ(kTerms.write_margin, absl::Seconds(3));
}

TEST(LeasePolicyTest, ANeverHeldLeaseIsTakenWithTokenOne) {
  const LeaseRecord none;
  EXPECT_TRUE(LeaseFree(none, At(0)));
  absl::StatusOr<LeaseRecord> a = NextLease("m", none, "A", 0, At(0), kTerms);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->holder, "A");
  EXPECT_EQ(a->token, 1u);
  EXPECT_EQ(a->expires, At(12));
  EXPECT_FALSE(LeaseFree(*a, At(11.9)));
  EXPECT_TRUE(LeaseFree(*a, At(12)));
}

TEST(LeasePolicyTest, ALiveLeaseOfAnotherHolderIsRefusedNamingItsGeneration) {
  LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  a.token = 7;
  absl::StatusOr<LeaseRecord> b = NextLease("m", a, "B", 0, At(5), kTerms);
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(b.status().message(),
              AllOf(HasSubstr("map \"m\""), HasSubstr("generation 7"), HasSubstr("holder A"),
                    HasSubstr("7.0 s more")));
  EXPECT_FALSE(IsLeaseLost(b.status())) << "B held nothing, so it lost nothing";
}

TEST(LeasePolicyTest, ARenewalKeepsTheTokenAndMovesTheExpiry) {
  const LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  absl::StatusOr<LeaseRecord> renewed = NextLease("m", a, "A", a.token, At(4), kTerms);
  ASSERT_TRUE(renewed.ok()) << renewed.status();
  EXPECT_EQ(renewed->token, a.token);
  EXPECT_EQ(renewed->expires, At(16));
  // Late but untouched: nobody took it, so nobody wrote the map; renewing is safe.
  absl::StatusOr<LeaseRecord> late = NextLease("m", a, "A", a.token, At(30), kTerms);
  ASSERT_TRUE(late.ok()) << late.status();
  EXPECT_EQ(late->token, a.token);
  EXPECT_EQ(late->expires, At(42));
}

TEST(LeasePolicyTest, AnExpiredLeaseIsTakenOverWithAHigherTokenAndTheOldHolderHasLostIt) {
  const LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  EXPECT_FALSE(NextLease("m", a, "B", 0, At(11.9), kTerms).ok());
  absl::StatusOr<LeaseRecord> b = NextLease("m", a, "B", 0, At(12), kTerms);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->holder, "B");
  EXPECT_EQ(b->token, 2u);
  // A comes back (it was paused): neither a renewal nor a write goes through, even if B's
  // lease has itself expired by now.
  for (double t : {13.0, 100.0}) {
    absl::StatusOr<LeaseRecord> renew = NextLease("m", *b, "A", a.token, At(t), kTerms);
    ASSERT_FALSE(renew.ok());
    EXPECT_TRUE(IsLeaseLost(renew.status())) << renew.status();
    EXPECT_THAT(renew.status().message(),
                AllOf(HasSubstr("generation 1"), HasSubstr("taken over by generation 2"),
                      HasSubstr("holder B")));
    const absl::Status write = CheckFence("m", *b, "A", a.token, At(t), kTerms);
    EXPECT_EQ(write.code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_TRUE(IsLeaseLost(write)) << write;
  }
  // A may take it again only as a new holder of a new generation, once it is free.
  absl::StatusOr<LeaseRecord> again = NextLease("m", *b, "A", 0, At(100), kTerms);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->token, 3u);
}

TEST(LeasePolicyTest, WritesNeedTheHeldTokenAndTheMarginLeft) {
  const LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  EXPECT_TRUE(CheckFence("m", a, "A", a.token, At(0), kTerms).ok());
  EXPECT_TRUE(CheckFence("m", a, "A", a.token, At(9), kTerms).ok());
  // Within the last write_margin: refused, but not lost (a renewal may still keep it).
  for (double t : {9.5, 12.0, 20.0}) {
    const absl::Status late = CheckFence("m", a, "A", a.token, At(t), kTerms);
    EXPECT_EQ(late.code(), absl::StatusCode::kFailedPrecondition) << t;
    EXPECT_FALSE(IsLeaseLost(late)) << late;
    EXPECT_THAT(late.message(), HasSubstr("not renewed in time"));
  }
  // Another holder, a wrong token, or no token at all: lost.
  EXPECT_TRUE(IsLeaseLost(CheckFence("m", a, "B", a.token, At(1), kTerms)));
  EXPECT_TRUE(IsLeaseLost(CheckFence("m", a, "A", a.token + 1, At(1), kTerms)));
  EXPECT_TRUE(IsLeaseLost(CheckFence("m", a, "A", 0, At(1), kTerms)));
  EXPECT_TRUE(IsLeaseLost(CheckFence("m", LeaseRecord{}, "A", 1, At(1), kTerms)));
}

TEST(LeasePolicyTest, AReleasedLeaseIsFreeAtOnceAndTokensKeepGrowing) {
  const LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  const LeaseRecord released = ReleasedLease(a);
  EXPECT_EQ(released.token, a.token);
  EXPECT_TRUE(LeaseFree(released, At(1)));
  EXPECT_FALSE(CheckFence("m", released, "A", a.token, At(1), kTerms).ok());
  absl::StatusOr<LeaseRecord> b = NextLease("m", released, "B", 0, At(1), kTerms);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->token, 2u);
}

TEST(LeasePolicyTest, AHolderAskingAgainForItsOwnLiveLeaseTakesANewGeneration) {
  // It dropped the map (or never knew its token): whatever used the old token is fenced off.
  const LeaseRecord a = *NextLease("m", LeaseRecord{}, "A", 0, At(0), kTerms);
  absl::StatusOr<LeaseRecord> again = NextLease("m", a, "A", 0, At(1), kTerms);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->token, 2u);
  EXPECT_TRUE(IsLeaseLost(CheckFence("m", *again, "A", a.token, At(1), kTerms)));
}

TEST(LeasePolicyTest, HolderIdsAreSafeInFileNamesAndLogs) {
  EXPECT_EQ(MakeHolderId("node-1.example.com", 42, 0xabc),
            "node_1.example.com-42-0000000000000abc");
  EXPECT_EQ(MakeHolderId("a b/c\n", 7, 1), "a_b_c_-7-0000000000000001");
  EXPECT_EQ(MakeHolderId("", 7, 1), "host-7-0000000000000001");
  EXPECT_EQ(MakeHolderId(std::string(100, 'h'), 1, 2).size(), 64u + 3 + 16);  // "-1-"
  EXPECT_NE(MakeHolderId("h", 1, 2), MakeHolderId("h", 1, 3));
}

}  // namespace
}  // namespace plx

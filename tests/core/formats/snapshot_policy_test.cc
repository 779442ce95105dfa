// The snapshot rule (core/formats/snapshot_policy.h): a map is due once its oldest unsaved
// change is an interval old, never while a save of it runs, and changes made during a save
// count from when they were made.
#include "core/formats/snapshot_policy.h"

#include <gtest/gtest.h>

namespace plx {
namespace {

const absl::Time kT0 = absl::FromUnixSeconds(1000000);
const absl::Duration kInterval = absl::Seconds(30);

absl::Time At(double seconds) { return kT0 + absl::Seconds(seconds); }

TEST(SnapshotPolicyTest, ACleanMapIsNeverDue) {
  MapSaveState s;
  s.MarkClean(1);
  EXPECT_FALSE(s.dirty());
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(1e6)));
  EXPECT_EQ(s.NextSnapshotDue(kInterval), absl::InfiniteFuture());
}

TEST(SnapshotPolicyTest, DueAnIntervalAfterTheOldestUnsavedChange) {
  MapSaveState s;
  s.MarkClean(1);
  s.Changed(2, At(0));
  s.Changed(3, At(10));  // later changes do not push the snapshot back
  s.Changed(4, At(29));
  EXPECT_TRUE(s.dirty());
  EXPECT_EQ(s.unsaved_since(), At(0));
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(29.9)));
  EXPECT_TRUE(s.SnapshotDue(kInterval, At(30)));
  EXPECT_EQ(s.NextSnapshotDue(kInterval), At(30));
}

TEST(SnapshotPolicyTest, OffWithAZeroInterval) {
  MapSaveState s;
  s.Changed(2, At(0));
  EXPECT_FALSE(s.SnapshotDue(absl::ZeroDuration(), At(1e6)));
  EXPECT_EQ(s.NextSnapshotDue(absl::ZeroDuration()), absl::InfiniteFuture());
}

TEST(SnapshotPolicyTest, NeverWhileASaveRuns) {
  MapSaveState s;
  s.Changed(2, At(0));
  s.SaveStarted(2, At(99));
  EXPECT_TRUE(s.saving());
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(100)));
  s.SaveFinished(true, At(101));
  EXPECT_FALSE(s.saving());
  EXPECT_FALSE(s.dirty());
  EXPECT_EQ(s.saved_version(), 2u);
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(1000)));
}

TEST(SnapshotPolicyTest, ChangesDuringASaveCountFromWhenTheyWereMade) {
  MapSaveState s;
  s.Changed(2, At(0));
  s.SaveStarted(2, At(30));
  s.Changed(3, At(30.5));  // not in the file being written
  s.Changed(4, At(30.8));
  s.SaveFinished(true, At(31));
  EXPECT_TRUE(s.dirty());
  EXPECT_EQ(s.saved_version(), 2u);
  EXPECT_EQ(s.unsaved_since(), At(30.5));
  // Due an interval after that change, less the 1 s the last save took.
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(59.4)));
  EXPECT_TRUE(s.SnapshotDue(kInterval, At(59.5)));
  // A save of the newest version leaves it clean.
  s.SaveStarted(4, At(60));
  s.SaveFinished(true, At(61));
  EXPECT_FALSE(s.dirty());
  EXPECT_EQ(s.saved_version(), 4u);
}

// A save takes time, and the changes it writes are only safe when it ends: it starts early by
// what the last one took, so the file holds a change about an interval after it was made.
TEST(SnapshotPolicyTest, ASnapshotStartsEarlyByWhatTheLastSaveTook) {
  MapSaveState s;
  s.Changed(2, At(0));
  EXPECT_EQ(s.NextSnapshotDue(kInterval), At(30));  // no save yet: nothing known
  s.SaveStarted(2, At(30));
  s.SaveFinished(true, At(38));  // 8 s
  s.Changed(3, At(100));
  EXPECT_EQ(s.NextSnapshotDue(kInterval), At(122));
  // Never earlier than the change itself, however slow the last save was.
  s.SaveStarted(3, At(122));
  s.SaveFinished(true, At(200));  // 78 s, longer than the interval
  s.Changed(4, At(300));
  EXPECT_EQ(s.NextSnapshotDue(kInterval), At(300));
}

TEST(SnapshotPolicyTest, AFailedSaveKeepsTheChangesAndWaitsBeforeTheNextTry) {
  MapSaveState s;
  s.Changed(2, At(0));
  s.SaveStarted(2, At(30));
  s.SaveFinished(false, At(31), kInterval);
  EXPECT_TRUE(s.dirty());
  EXPECT_EQ(s.saved_version(), 0u);
  EXPECT_EQ(s.unsaved_since(), At(0));  // still the oldest change at risk
  EXPECT_FALSE(s.SnapshotDue(kInterval, At(60)));
  EXPECT_TRUE(s.SnapshotDue(kInterval, At(61)));
  // A later success ends the wait.
  s.SaveStarted(2, At(61));
  s.SaveFinished(true, At(62));
  EXPECT_FALSE(s.dirty());
}

TEST(SnapshotPolicyTest, LoadingMarksTheFilesVersionClean) {
  MapSaveState s;
  s.Changed(5, At(0));
  s.MarkClean(9);
  EXPECT_FALSE(s.dirty());
  EXPECT_EQ(s.version(), 9u);
  EXPECT_EQ(s.saved_version(), 9u);
  EXPECT_EQ(s.unsaved_since(), absl::InfiniteFuture());
}

}  // namespace
}  // namespace plx

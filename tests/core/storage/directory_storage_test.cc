// Shared map storage in a directory (core/storage/directory_storage.h), two storage objects on
// one folder acting as two daemons, on a fake clock: leases are swapped only from the revision
// read, and a fenced write publishes nothing once the writer's lease was taken over, whether
// the takeover came before its write or while it was writing (the check that counts is the
// one made under the lock, just before the rename).
#include "core/storage/directory_storage.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/io/atomic_write.h"
#include "tests/test_util.h"

namespace plx {
namespace {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

const LeaseTerms kTerms = LeaseTermsFor(absl::Seconds(12));

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Files in `dir` whose names contain `part`.
std::vector<std::string> FilesWith(const std::string& dir, const std::string& part) {
  std::vector<std::string> out;
  for (const fs::directory_entry& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.find(part) != std::string::npos) out.push_back(name);
  }
  return out;
}

// Two daemons' views of one shared folder, with one clock they both read.
class DirectoryStorageTest : public ::testing::Test {
 protected:
  DirectoryStorageTest()
      : dir_(testing::MakeTempDir("plx_dir_storage")),
        a_(DirectoryStorageOptions{dir_, absl::Milliseconds(200), "A-1-01"}),
        b_(DirectoryStorageOptions{dir_, absl::Milliseconds(200), "B-2-02"}) {}
  ~DirectoryStorageTest() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::function<absl::Time()> Clock() {
    return [this] { return now_; };
  }
  MapStorage::LeaseCheck Fence(const std::string& holder, uint64_t token) {
    return [this, holder, token](const LeaseRecord& current) {
      return CheckFence("m", current, holder, token, now_, kTerms);
    };
  }
  // A FileWriter that writes `bytes` (atomically, as SaveMap does) and counts its calls.
  MapStorage::FileWriter Writes(const std::string& bytes, int* calls) {
    return [bytes, calls](const std::string& path) {
      ++*calls;
      return WriteFileAtomically(path, bytes, "test map");
    };
  }

  const std::string dir_;
  DirectoryMapStorage a_, b_;
  absl::Time now_ = absl::FromUnixSeconds(1000000);
};

TEST_F(DirectoryStorageTest, LeaseRecordsRoundTripAndSwapOnlyFromTheRevisionRead) {
  absl::StatusOr<LeaseRecord> none = a_.ReadLease("m");
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_EQ(none->token, 0u);
  EXPECT_EQ(none->revision, 0u);
  LeaseRecord next;
  next.holder = "A-1-01";
  next.token = 1;
  next.expires = now_ + absl::Seconds(12);
  absl::StatusOr<LeaseRecord> stored = a_.SwapLease("m", 0, next);
  ASSERT_TRUE(stored.ok()) << stored.status();
  EXPECT_EQ(stored->revision, 1u);
  absl::StatusOr<LeaseRecord> seen = b_.ReadLease("m");
  ASSERT_TRUE(seen.ok()) << seen.status();
  EXPECT_EQ(seen->holder, "A-1-01");
  EXPECT_EQ(seen->token, 1u);
  EXPECT_EQ(seen->expires, now_ + absl::Seconds(12));
  EXPECT_EQ(seen->revision, 1u);
  // B decided on revision 0 (before A's swap): refused, A's record stays.
  LeaseRecord late = next;
  late.holder = "B-2-02";
  late.expires = now_;
  absl::StatusOr<LeaseRecord> stale = b_.SwapLease("m", 0, late);
  EXPECT_EQ(stale.status().code(), absl::StatusCode::kAborted) << stale.status();
  EXPECT_EQ(a_.ReadLease("m")->holder, "A-1-01");
}

TEST_F(DirectoryStorageTest, ADamagedLeaseRecordIsDataLoss) {
  std::ofstream(a_.LeasePath("m")) << "plenoxd-lease 1\nholder A\ntoken x\n";
  EXPECT_EQ(a_.ReadLease("m").status().code(), absl::StatusCode::kDataLoss);
  std::ofstream(a_.LeasePath("n")) << "something else\n";
  EXPECT_EQ(a_.ReadLease("n").status().code(), absl::StatusCode::kDataLoss);
  // A damaged record is never overwritten by a take: the fence cannot be read.
  EXPECT_FALSE(AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms).ok());
}

TEST_F(DirectoryStorageTest, OnlyTheLeaseHolderTakesAndTheNextHolderGetsAHigherToken) {
  absl::StatusOr<LeaseRecord> a = AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->token, 1u);
  absl::StatusOr<LeaseRecord> refused = AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.status().message(), HasSubstr("holder A-1-01"));
  now_ += absl::Seconds(4);
  ASSERT_TRUE(AcquireLease(a_, "m", "A-1-01", a->token, Clock(), kTerms).ok());  // renewed
  now_ += absl::Seconds(11);  // 15 s after the take, 11 after the renewal: still A's
  EXPECT_FALSE(AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms).ok());
  now_ += absl::Seconds(1);
  absl::StatusOr<LeaseRecord> b = AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->token, 2u);
  absl::StatusOr<LeaseRecord> renew = AcquireLease(a_, "m", "A-1-01", a->token, Clock(), kTerms);
  EXPECT_TRUE(IsLeaseLost(renew.status())) << renew.status();
  // Released by B: A takes it at once, a generation higher still.
  ASSERT_TRUE(ReleaseLease(b_, "m", "B-2-02", b->token).ok());
  absl::StatusOr<LeaseRecord> again = AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->token, 3u);
  // Releasing a lease one no longer holds changes nothing.
  ASSERT_TRUE(ReleaseLease(b_, "m", "B-2-02", b->token).ok());
  EXPECT_EQ(a_.ReadLease("m")->holder, "A-1-01");
}

TEST_F(DirectoryStorageTest, AFencedOwnerWritesNothingAfterATakeover) {
  const LeaseRecord a = *AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  int a_writes = 0, b_writes = 0;
  ASSERT_TRUE(a_.WriteFenced("m", Fence("A-1-01", a.token), Writes("A's first", &a_writes)).ok());
  EXPECT_EQ(ReadAll(a_.MapPath("m")), "A's first");
  // A is paused past its expiry; B takes the map over and saves it.
  now_ += absl::Seconds(13);
  const LeaseRecord b = *AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms);
  ASSERT_TRUE(b_.WriteFenced("m", Fence("B-2-02", b.token), Writes("B's", &b_writes)).ok());
  struct stat before;
  ASSERT_EQ(::stat(a_.MapPath("m").c_str(), &before), 0);
  // A resumes and saves under its old token: refused before anything is written.
  a_writes = 0;
  const absl::Status fenced =
      a_.WriteFenced("m", Fence("A-1-01", a.token), Writes("A's second", &a_writes));
  EXPECT_TRUE(IsLeaseLost(fenced)) << fenced;
  EXPECT_THAT(fenced.message(), HasSubstr("taken over by generation 2"));
  EXPECT_EQ(a_writes, 0) << "the fenced owner did not even write a staging file";
  EXPECT_EQ(ReadAll(a_.MapPath("m")), "B's");
  struct stat after;
  ASSERT_EQ(::stat(a_.MapPath("m").c_str(), &after), 0);
  EXPECT_EQ(after.st_ino, before.st_ino) << "the file was not replaced";
  EXPECT_THAT(FilesWith(dir_, ".stage."), ::testing::IsEmpty());
  // Nor may A delete it.
  EXPECT_TRUE(IsLeaseLost(a_.RemoveFenced("m", Fence("A-1-01", a.token))));
  EXPECT_EQ(ReadAll(a_.MapPath("m")), "B's");
}

TEST_F(DirectoryStorageTest, TheFenceIsCheckedAgainWhenTheFileIsPublished) {
  // A passes the first check, then (while it writes: paused, or a slow volume) its lease
  // expires and B takes the map and publishes its own file. A's rename must not happen.
  const LeaseRecord a = *AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  int b_writes = 0;
  const absl::Status fenced =
      a_.WriteFenced("m", Fence("A-1-01", a.token), [&](const std::string& path) {
        EXPECT_TRUE(WriteFileAtomically(path, "A's late", "test map").ok());
        now_ += absl::Seconds(13);
        const LeaseRecord b = *AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms);
        EXPECT_TRUE(
            b_.WriteFenced("m", Fence("B-2-02", b.token), Writes("B's", &b_writes)).ok());
        return absl::OkStatus();
      });
  EXPECT_TRUE(IsLeaseLost(fenced)) << fenced;
  EXPECT_EQ(b_writes, 1);
  EXPECT_EQ(ReadAll(a_.MapPath("m")), "B's");
  EXPECT_THAT(FilesWith(dir_, ".stage."), ::testing::IsEmpty()) << "A's staging file removed";
}

TEST_F(DirectoryStorageTest, AnExpiredButUntakenLeaseStopsWritesUntilRenewed) {
  const LeaseRecord a = *AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  now_ += absl::Seconds(10);  // 2 s left, under the 3 s margin
  int writes = 0;
  const absl::Status late = a_.WriteFenced("m", Fence("A-1-01", a.token), Writes("x", &writes));
  EXPECT_EQ(late.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_FALSE(IsLeaseLost(late));
  EXPECT_EQ(writes, 0);
  EXPECT_FALSE(fs::exists(a_.MapPath("m")));
  ASSERT_TRUE(AcquireLease(a_, "m", "A-1-01", a.token, Clock(), kTerms).ok());
  EXPECT_TRUE(a_.WriteFenced("m", Fence("A-1-01", a.token), Writes("x", &writes)).ok());
  EXPECT_EQ(ReadAll(a_.MapPath("m")), "x");
}

TEST_F(DirectoryStorageTest, ListsStatsAndReadsOnlyMapFiles) {
  const LeaseRecord a = *AcquireLease(a_, "m", "A-1-01", 0, Clock(), kTerms);
  const LeaseRecord n = *AcquireLease(a_, "n", "A-1-01", 0, Clock(), kTerms);
  int writes = 0;
  ASSERT_TRUE(a_.WriteFenced("n", [&](const LeaseRecord& c) {
    return CheckFence("n", c, "A-1-01", n.token, now_, kTerms);
  }, Writes("12345", &writes)).ok());
  ASSERT_TRUE(a_.WriteFenced("m", Fence("A-1-01", a.token), Writes("abc", &writes)).ok());
  fs::create_directory(dir_ + "/dir.plx");  // not a regular file: not a map
  absl::StatusOr<std::vector<std::string>> names = b_.List();
  ASSERT_TRUE(names.ok()) << names.status();
  EXPECT_THAT(*names, ElementsAre("m", "n"));  // not leases, locks or folders
  absl::StatusOr<StoredMapInfo> info = b_.Stat("n");
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->bytes, 5);
  EXPECT_EQ(b_.Stat("other").status().code(), absl::StatusCode::kNotFound);
  absl::StatusOr<std::string> path = b_.LocalPath("m");
  ASSERT_TRUE(path.ok()) << path.status();
  EXPECT_EQ(ReadAll(*path), "abc");
  EXPECT_EQ(b_.LocalPath("other").status().code(), absl::StatusCode::kNotFound);
  // Deleting keeps the lease record, so the next holder's token is still higher.
  ASSERT_TRUE(a_.RemoveFenced("m", Fence("A-1-01", a.token)).ok());
  EXPECT_EQ(b_.Stat("m").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(b_.ReadLease("m")->token, a.token);
}

TEST_F(DirectoryStorageTest, ALockHeldByAStoppedProcessMakesOthersGiveUpNotWrite) {
  // What another process's flock looks like from here: a separate open file description.
  const std::string lock_path = a_.MapPath("m") + ".lock";
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX), 0);
  absl::StatusOr<LeaseRecord> blocked = AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms);
  EXPECT_EQ(blocked.status().code(), absl::StatusCode::kUnavailable) << blocked.status();
  EXPECT_THAT(blocked.status().message(), HasSubstr("stayed locked"));
  EXPECT_EQ(b_.ReadLease("m")->token, 0u);
  ::flock(fd, LOCK_UN);
  ::close(fd);
  EXPECT_TRUE(AcquireLease(b_, "m", "B-2-02", 0, Clock(), kTerms).ok());
}

TEST_F(DirectoryStorageTest, StaleStagingFilesAreRemovedFreshOnesKept) {
  const std::string old_file = a_.MapPath("m") + ".stage.X-9-09";
  const std::string old_temp = old_file + ".tmp.123";
  const std::string fresh = a_.MapPath("m") + ".stage.Y-8-08";
  for (const std::string& p : {old_file, old_temp, fresh}) std::ofstream(p) << "partial";
  const absl::Time real_now = absl::Now();
  for (const std::string& p : {old_file, old_temp}) {
    const timespec times[2] = {absl::ToTimespec(real_now - absl::Hours(2)),
                               absl::ToTimespec(real_now - absl::Hours(2))};
    ASSERT_EQ(::utimensat(AT_FDCWD, p.c_str(), times, 0), 0);
  }
  std::ofstream(a_.MapPath("m")) << "map";
  const std::vector<StaleTempFile> removed = a_.RemoveStaleStaging(absl::Hours(1), real_now);
  ASSERT_EQ(removed.size(), 2u);
  for (const StaleTempFile& r : removed) EXPECT_TRUE(r.removed.ok()) << r.removed;
  EXPECT_FALSE(fs::exists(old_file));
  EXPECT_FALSE(fs::exists(old_temp));
  EXPECT_TRUE(fs::exists(fresh));
  EXPECT_TRUE(fs::exists(a_.MapPath("m")));
}

}  // namespace
}  // namespace plx

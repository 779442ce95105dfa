// Handoff between map stores on shared storage (server/map_store.h, "Handoff"): two or three
// stores on one folder acting as daemons behind a router whose ring changed, on a fake lease
// clock. A call naming a map another store holds asks for it (UNAVAILABLE); the holder gives it
// up at its next renewal only once no mapping job holds it and no call has named it for a
// third of the lease (saving unsaved changes under the fence), and the released lease waits
// for the requester; a request nobody renews lapses.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/storage/directory_storage.h"
#include "server/map_store.h"
#include "tests/server/published_map.h"
#include "tests/test_util.h"

namespace plx::server {
namespace map_store_handoff_test {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

constexpr float kVoxel = 0.05f;

// A map as a mapping job publishes it (tests/server/published_map.h), at this file's voxel size.
std::shared_ptr<const PlenoxelMap> MapWithBricks(int bricks, bool refresh = true) {
  return plx::testing::MapWithBricks(kVoxel, bricks, refresh);
}

class MapHandoffTest : public ::testing::Test {
 protected:
  ~MapHandoffTest() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // A lease of 12 s: renewals every 4 s, a holder idle for 4 s gives a wanted map up, and a
  // request lasts 12 s.
  std::unique_ptr<MapStore> Store(const std::string& holder) {
    MapStoreOptions o;
    o.shared = std::make_shared<DirectoryMapStorage>(
        DirectoryStorageOptions{dir_, absl::Seconds(1), holder});
    o.holder = holder;
    o.lease = LeaseTermsFor(absl::Seconds(12));
    o.clock = [this] { return now_; };
    return std::make_unique<MapStore>(o);
  }
  LeaseRecord Lease(const std::string& name = "m") {
    DirectoryMapStorage view(DirectoryStorageOptions{dir_, absl::Seconds(1), "test"});
    absl::StatusOr<LeaseRecord> lease = view.ReadLease(name);
    EXPECT_TRUE(lease.ok()) << lease.status();
    return lease.ok() ? *lease : LeaseRecord{};
  }
  // What the holder's lease keeper does every renewal.
  std::vector<MapHandoffEvent> KeeperRound(MapStore& store) {
    EXPECT_THAT(store.RenewLeases(), IsEmpty());
    return store.HandOffWanted();
  }

  const std::string dir_ = plx::testing::MakeTempDir("plx_handoff_store");
  absl::Time now_ = absl::FromUnixSeconds(1000000);
  std::unique_ptr<MapStore> a_ = Store("A-1-01");
  std::unique_ptr<MapStore> b_ = Store("B-2-02");
};

TEST_F(MapHandoffTest, AnIdleHolderSavesAndReleasesAWantedMapAndTheRequesterLoadsIt) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(3), 1).ok());
  ASSERT_TRUE(a_->Save("m").ok());
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(5), 1).ok());  // not saved yet
  const uint64_t version = a_->List()[0].version;

  absl::StatusOr<MapStatus> asked = b_->Info("m");
  ASSERT_FALSE(asked.ok());
  EXPECT_EQ(asked.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(asked.status().message(),
              AllOf(HasSubstr("holder A-1-01"), HasSubstr("asked it to hand the map over"),
                    HasSubstr("retry")));
  EXPECT_EQ(Lease().wanted_by, "B-2-02");
  EXPECT_EQ(Lease().holder, "A-1-01");

  // A was called a moment ago (the Save): it keeps the map for now.
  EXPECT_THAT(KeeperRound(*a_), IsEmpty());
  EXPECT_EQ(a_->leases_held(), 1);
  now_ += absl::Seconds(4);
  const std::vector<MapHandoffEvent> given = KeeperRound(*a_);
  ASSERT_EQ(given.size(), 1u);
  EXPECT_TRUE(given[0].status.ok()) << given[0].status;
  EXPECT_EQ(given[0].name, "m");
  EXPECT_EQ(given[0].to, "B-2-02");
  EXPECT_EQ(given[0].version, version);
  EXPECT_TRUE(given[0].saved) << "its unsaved changes were written first";
  EXPECT_THAT(a_->List(), IsEmpty());
  EXPECT_EQ(a_->leases_held(), 0);
  EXPECT_EQ(a_->handoffs_given(), 1);
  EXPECT_EQ(a_->lease_losses(), 0) << "given, not lost";
  EXPECT_TRUE(LeaseFree(Lease(), now_));
  EXPECT_EQ(Lease().wanted_by, "B-2-02") << "reserved for B";

  // B's retry loads what A saved, a generation higher.
  absl::StatusOr<MapVersion> loaded = b_->Latest("m");
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->map->grid.num_bricks(), 5);
  EXPECT_EQ(loaded->version, version);
  EXPECT_EQ(Lease().holder, "B-2-02");
  EXPECT_EQ(Lease().token, 2u);
  EXPECT_TRUE(Lease().wanted_by.empty());
  EXPECT_EQ(b_->handoffs_taken(), 1);
  EXPECT_EQ(a_->fenced_saves_refused() + b_->fenced_saves_refused(), 0);
}

TEST_F(MapHandoffTest, AMappingJobOrARecentCallDefersTheHandoff) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  ASSERT_TRUE(a_->BeginMapping("m", MappingJobKind::kSlam).ok());
  ASSERT_FALSE(b_->Info("m").ok());
  now_ += absl::Seconds(5);
  EXPECT_THAT(KeeperRound(*a_), IsEmpty()) << "a Slam job is writing it";
  a_->EndMapping("m");
  ASSERT_EQ(b_->Info("m").status().code(), absl::StatusCode::kUnavailable);  // asks again
  ASSERT_TRUE(a_->Info("m").ok());  // a client of A still calls
  now_ += absl::Seconds(2);
  EXPECT_THAT(KeeperRound(*a_), IsEmpty()) << "called 2 s ago";
  now_ += absl::Seconds(2);
  const std::vector<MapHandoffEvent> given = KeeperRound(*a_);
  ASSERT_EQ(given.size(), 1u);
  EXPECT_TRUE(given[0].saved) << "a map never saved is written so B can load it";
  ASSERT_TRUE(b_->Info("m").ok());
  EXPECT_EQ(Lease().holder, "B-2-02");
}

TEST_F(MapHandoffTest, AReleasedMapIsReservedForItsRequesterNotTakenBackOrSideways) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  ASSERT_FALSE(b_->Info("m").ok());
  now_ += absl::Seconds(4);
  ASSERT_EQ(KeeperRound(*a_).size(), 1u);
  // A stray call on A, and a third daemon: the map is B's to take.
  std::unique_ptr<MapStore> c = Store("C-3-03");
  for (MapStore* other : {a_.get(), c.get()}) {
    absl::StatusOr<MapStatus> refused = other->Info("m");
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnavailable) << refused.status();
    EXPECT_THAT(refused.status().message(), HasSubstr("moving to daemon B-2-02"));
  }
  EXPECT_EQ(Lease().wanted_by, "B-2-02");
  ASSERT_TRUE(b_->Info("m").ok());
  // B now serves it; C's request waits for B to go idle, then C gets it.
  ASSERT_EQ(c->Info("m").status().code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(KeeperRound(*b_), IsEmpty()) << "B just loaded it for a call";
  now_ += absl::Seconds(4);
  ASSERT_EQ(KeeperRound(*b_).size(), 1u);
  ASSERT_TRUE(c->Info("m").ok());
  EXPECT_EQ(Lease().token, 3u);
}

TEST_F(MapHandoffTest, ARequestNobodyRenewsLapsesAndTheBusyHolderKeepsTheMap) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  ASSERT_FALSE(b_->Info("m").ok());  // B asks once, then its router changes its mind
  for (int i = 0; i < 4; ++i) {
    now_ += absl::Seconds(3);
    ASSERT_TRUE(a_->Info("m").ok()) << i;  // A's clients keep calling
    EXPECT_THAT(KeeperRound(*a_), IsEmpty()) << i;
  }
  now_ += absl::Seconds(10);  // A idle now, but the request has lapsed
  EXPECT_THAT(KeeperRound(*a_), IsEmpty());
  EXPECT_EQ(a_->leases_held(), 1);
  EXPECT_EQ(a_->handoffs_given(), 0);
}

TEST_F(MapHandoffTest, AStoreThatLostAMapAnswersWithTheLossForTwoTermsThenAsksAgain) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(1), 1).ok());
  ASSERT_TRUE(a_->Save("m").ok());
  now_ += absl::Seconds(13);  // A stalled past its lease; B takes the map over
  ASSERT_TRUE(b_->Info("m").ok());
  ASSERT_EQ(a_->RenewLeases().size(), 1u);  // A resumes and finds the loss
  absl::StatusOr<MapStatus> lost = a_->Info("m");
  EXPECT_EQ(lost.status().code(), absl::StatusCode::kFailedPrecondition) << lost.status();
  EXPECT_THAT(lost.status().message(), HasSubstr("generation 2"));
  now_ += absl::Seconds(24);
  ASSERT_TRUE(b_->RenewLeases().empty());
  absl::StatusOr<MapStatus> asked = a_->Info("m");
  EXPECT_EQ(asked.status().code(), absl::StatusCode::kUnavailable) << asked.status();
  EXPECT_EQ(Lease().wanted_by, "A-1-01");
}

}  // namespace map_store_handoff_test
}  // namespace plx::server

// The map store on shared storage (MapStore with MapStoreOptions::shared), two stores on one
// folder acting as two daemons, on a fake lease clock: calls naming a stored map load it on
// demand under its lease, a store whose lease was taken over writes nothing (the save is
// refused at the fence, the map dropped, calls get the error naming the new generation), and
// leases are renewed, released and bounded by --max-maps.
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
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
namespace map_store_lease_test {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

constexpr float kVoxel = 0.05f;

// A map as a mapping job publishes it (tests/server/published_map.h), at this file's voxel size.
std::shared_ptr<const PlenoxelMap> MapWithBricks(int bricks, bool refresh = true) {
  return plx::testing::MapWithBricks(kVoxel, bricks, refresh);
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class SharedMapStoreTest : public ::testing::Test {
 protected:
  ~SharedMapStoreTest() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::unique_ptr<MapStore> Store(const std::string& holder, int max_maps = 16) {
    MapStoreOptions o;
    o.max_maps = max_maps;
    o.shared = std::make_shared<DirectoryMapStorage>(
        DirectoryStorageOptions{dir_, absl::Seconds(1), holder});
    o.holder = holder;
    o.lease = LeaseTermsFor(absl::Seconds(12));
    o.clock = [this] { return now_; };
    return std::make_unique<MapStore>(o);
  }
  // A map "m" made on `store`, with `bricks` bricks, saved to the shared folder.
  void MakeSaved(MapStore& store, const std::string& name = "m", int bricks = 2) {
    ASSERT_TRUE(store.Create(name, kVoxel).ok());
    ASSERT_TRUE(store.Publish(name, MapWithBricks(bricks), 1).ok());
    ASSERT_TRUE(store.Save(name).ok());
  }
  std::string MapPath(const std::string& name = "m") const { return dir_ + "/" + name + ".plx"; }
  LeaseRecord Lease(const std::string& name = "m") {
    DirectoryMapStorage view(DirectoryStorageOptions{dir_, absl::Seconds(1), "test"});
    absl::StatusOr<LeaseRecord> lease = view.ReadLease(name);
    EXPECT_TRUE(lease.ok()) << lease.status();
    return lease.ok() ? *lease : LeaseRecord{};
  }

  const std::string dir_ = plx::testing::MakeTempDir("plx_shared_store");
  absl::Time now_ = absl::FromUnixSeconds(1000000);
  std::unique_ptr<MapStore> a_ = Store("A-1-01");
  std::unique_ptr<MapStore> b_ = Store("B-2-02");
};

TEST_F(SharedMapStoreTest, ACallNamingAStoredMapLoadsItOnceItsLeaseIsFree) {
  MakeSaved(*a_, "m", 3);
  EXPECT_THAT(b_->List(), IsEmpty()) << "nothing is loaded before a call names it";
  absl::StatusOr<MapStatus> held = b_->Info("m");
  ASSERT_FALSE(held.ok());
  // B asked A for it (map_store_handoff_test.cc): retryable.
  EXPECT_EQ(held.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(held.status().message(),
              AllOf(HasSubstr("is in shared storage"), HasSubstr("owned by another daemon"),
                    HasSubstr("generation 1"), HasSubstr("holder A-1-01")));
  now_ += absl::Seconds(12);  // A stopped renewing (it died)
  absl::StatusOr<MapVersion> loaded = b_->Latest("m");
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->map->grid.num_bricks(), 3);
  EXPECT_EQ(loaded->version, a_->Info("m")->version) << "the saved version number carries on";
  EXPECT_EQ(b_->List().size(), 1u);
  EXPECT_EQ(b_->leases_held(), 1);
  EXPECT_EQ(Lease().holder, "B-2-02");
  EXPECT_EQ(Lease().token, 2u);
  // A name that is not stored is still NotFound, and takes no lease.
  EXPECT_EQ(b_->Info("other").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(Lease("other").token, 0u);
}

TEST_F(SharedMapStoreTest, AFencedOwnersSaveWritesNothingAndDropsTheMap) {
  MakeSaved(*a_);
  // A is paused past its lease; B takes the map over and saves it.
  now_ += absl::Seconds(13);
  ASSERT_TRUE(b_->Latest("m").ok());
  ASSERT_TRUE(b_->Publish("m", MapWithBricks(4), 1).ok());
  ASSERT_TRUE(b_->Save("m").ok());
  const std::string b_bytes = ReadAll(MapPath());
  // A resumes, with changes of its own, and saves before any renewal ran.
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(5), 1).ok());
  ASSERT_THAT(a_->DirtyNames(), ::testing::ElementsAre("m"));
  absl::StatusOr<MapStatus> saved = a_->Save("m");
  ASSERT_FALSE(saved.ok());
  EXPECT_EQ(saved.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(IsLeaseLost(saved.status())) << saved.status();
  EXPECT_THAT(saved.status().message(),
              AllOf(HasSubstr("no longer owned by this daemon"), HasSubstr("generation 1"),
                    HasSubstr("taken over by generation 2"), HasSubstr("holder B-2-02")));
  EXPECT_EQ(ReadAll(MapPath()), b_bytes) << "the file is still B's";
  EXPECT_EQ(a_->fenced_saves_refused(), 1);
  EXPECT_EQ(a_->lease_losses(), 1);
  // The map is gone from A: no snapshot of it, no listing, and calls get the clear error.
  EXPECT_THAT(a_->List(), IsEmpty());
  EXPECT_THAT(a_->DirtyNames(), IsEmpty());
  EXPECT_THAT(a_->ClaimDueSnapshots(absl::Seconds(1), absl::InfiniteFuture()), IsEmpty());
  absl::StatusOr<MapVersion> latest = a_->Latest("m");
  ASSERT_FALSE(latest.ok());
  EXPECT_EQ(latest.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(latest.status().message(), HasSubstr("generation 2"));
  EXPECT_EQ(a_->Save("m").status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(ReadAll(MapPath()), b_bytes);
  for (const fs::directory_entry& e : fs::directory_iterator(dir_)) {
    EXPECT_EQ(e.path().string().find(".stage."), std::string::npos) << e.path();
  }
}

TEST_F(SharedMapStoreTest, ARenewalThatFindsATakeoverDropsTheMap) {
  MakeSaved(*a_);
  now_ += absl::Seconds(13);
  ASSERT_TRUE(b_->Info("m").ok());
  const std::vector<MapLeaseEvent> events = a_->RenewLeases();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].name, "m");
  EXPECT_TRUE(events[0].lost);
  EXPECT_THAT(events[0].status.message(), HasSubstr("taken over by generation 2"));
  EXPECT_THAT(a_->List(), IsEmpty());
  EXPECT_EQ(a_->leases_held(), 0);
  EXPECT_EQ(a_->Info("m").status().code(), absl::StatusCode::kFailedPrecondition);
  // Once B gives the map up, A may load B's copy again, a generation higher.
  ASSERT_THAT(b_->ReleaseLeases(), IsEmpty());
  ASSERT_TRUE(a_->Info("m").ok());
  EXPECT_EQ(Lease().token, 3u);
  EXPECT_EQ(Lease().holder, "A-1-01");
}

TEST_F(SharedMapStoreTest, RenewalsKeepTheMapAndAReleaseHandsItOverAtOnce) {
  MakeSaved(*a_);
  for (int i = 0; i < 10; ++i) {
    now_ += absl::Seconds(4);
    EXPECT_THAT(a_->RenewLeases(), IsEmpty()) << i;
    EXPECT_EQ(b_->Info("m").status().code(), absl::StatusCode::kUnavailable) << i;
  }
  EXPECT_EQ(Lease().token, 1u);
  EXPECT_THAT(a_->ReleaseLeases(), IsEmpty());
  ASSERT_TRUE(b_->Info("m").ok()) << "no wait for the expiry";
  EXPECT_EQ(Lease().token, 2u);
  // After its release A writes nothing, even with changes.
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(6), 1).ok());
  const std::string bytes = ReadAll(MapPath());
  EXPECT_FALSE(a_->Save("m").ok());
  EXPECT_EQ(ReadAll(MapPath()), bytes);
}

TEST_F(SharedMapStoreTest, ANewMapIsHeldUnderItsLeaseAndAStoredNameIsNotMadeAgain) {
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  EXPECT_EQ(Lease().holder, "A-1-01");
  absl::StatusOr<MapStatus> twin = b_->Create("m", kVoxel);
  EXPECT_EQ(twin.status().code(), absl::StatusCode::kFailedPrecondition) << twin.status();
  ASSERT_TRUE(a_->Publish("m", MapWithBricks(1), 1).ok());
  ASSERT_TRUE(a_->Save("m").ok());
  twin = b_->Create("m", kVoxel);
  EXPECT_EQ(twin.status().code(), absl::StatusCode::kAlreadyExists) << twin.status();
  EXPECT_THAT(twin.status().message(), HasSubstr("in shared storage"));
}

TEST_F(SharedMapStoreTest, OnDemandLoadsAreBoundedByMaxMapsAndTakeNoLeaseWhenRefused) {
  MakeSaved(*a_, "m");
  MakeSaved(*a_, "n");
  ASSERT_THAT(a_->ReleaseLeases(), IsEmpty());
  std::unique_ptr<MapStore> small = Store("C-3-03", /*max_maps=*/1);
  ASSERT_TRUE(small->Info("m").ok());
  absl::StatusOr<MapStatus> full = small->Info("n");
  ASSERT_FALSE(full.ok());
  EXPECT_EQ(full.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(full.status().message(),
              AllOf(HasSubstr("in shared storage"), HasSubstr("maximum of 1 maps")));
  EXPECT_NE(Lease("n").holder, "C-3-03");
  EXPECT_TRUE(b_->Info("n").ok()) << "the refused map's lease is free for another daemon";
}

TEST_F(SharedMapStoreTest, AMappingJobKeepsALostMapsTombstoneUntilItEnds) {
  MakeSaved(*a_);
  ASSERT_TRUE(a_->BeginMapping("m", MappingJobKind::kSlam).ok());
  now_ += absl::Seconds(13);
  ASSERT_TRUE(b_->Info("m").ok());
  ASSERT_EQ(a_->RenewLeases().size(), 1u);
  // The job's next publish is refused with the reason; nothing else sees the map.
  absl::StatusOr<uint64_t> published = a_->Publish("m", MapWithBricks(3), 1);
  ASSERT_FALSE(published.ok());
  EXPECT_THAT(published.status().message(), HasSubstr("taken over by generation 2"));
  EXPECT_THAT(a_->List(), IsEmpty());
  EXPECT_EQ(a_->size(), 1);
  a_->EndMapping("m");
  EXPECT_EQ(a_->size(), 0);
  EXPECT_EQ(a_->Info("m").status().code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(SharedMapStoreTest, OnlyTheOwnerDeletes) {
  MakeSaved(*a_);
  now_ += absl::Seconds(13);
  ASSERT_TRUE(b_->Info("m").ok());
  const absl::Status refused = a_->Delete("m");
  EXPECT_EQ(refused.code(), absl::StatusCode::kFailedPrecondition) << refused;
  EXPECT_TRUE(fs::exists(MapPath()));
  ASSERT_TRUE(b_->Delete("m").ok());
  EXPECT_FALSE(fs::exists(MapPath()));
  EXPECT_THAT(b_->List(), IsEmpty());
  // The record stays, released, so the name's next holder goes on counting.
  EXPECT_EQ(Lease().token, 2u);
  ASSERT_TRUE(a_->Create("m", kVoxel).ok());
  EXPECT_EQ(Lease().token, 3u);
}

}  // namespace map_store_lease_test
}  // namespace plx::server

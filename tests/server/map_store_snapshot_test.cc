// The map store's persistence beyond SaveMap (issue 24): keyframes and version numbers go into
// map files and come back at the next start; snapshots claim a due map once, write the newest
// version while mapping goes on, leave changes made meanwhile dirty, wait for (and are made
// pointless by) explicit saves, and are retried an interval after a failure.
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/formats/map_file.h"
#include "core/kernels/refresh_occupancy.h"
#include "server/map_store.h"
#include "tests/server/published_map.h"
#include "tests/test_util.h"

namespace plx::server {
namespace {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::IsEmpty;

constexpr float kVoxel = 0.05f;
const absl::Duration kInterval = absl::Seconds(30);

// A map as a mapping job publishes it (tests/server/published_map.h), at this file's voxel size.
std::shared_ptr<const PlenoxelMap> MapWithBricks(int bricks, bool refresh = true) {
  return testing::MapWithBricks(kVoxel, bricks, refresh);
}

// `count` keyframes along x, every second one with a few features.
std::shared_ptr<const MapKeyframes> Keyframes(int count) {
  auto keyframes = std::make_shared<MapKeyframes>();
  for (int i = 0; i < count; ++i) {
    MapKeyframe k;
    k.timestamp = 0.5 * i;
    k.pose = SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * i, 0, 0));
    k.intrinsics = {100, 100, 64, 48, 128, 96};
    if (i % 2 == 0) {
      auto f = std::make_shared<FrameFeatures>();
      f->pixels = {{10.5f, 20.5f}, {30.5f, 40.5f}};
      f->points = {{0.1f, 0.2f, 1.0f}, {-0.3f, 0.1f, 2.0f}};
      f->descriptors.resize(2);
      f->descriptors[1][5] = static_cast<uint8_t>(i);
      f->thumbnail_width = 2;
      f->thumbnail_height = 1;
      f->thumbnail = {0.5f, -0.5f};
      k.features = std::move(f);
    }
    keyframes->push_back(std::move(k));
  }
  return keyframes;
}

MapStoreOptions InDir(const std::string& dir, absl::Duration save_delay = absl::ZeroDuration()) {
  MapStoreOptions options;
  options.data_dir = dir;
  options.test_only_save_delay = save_delay;
  return options;
}

class MapStoreSnapshotTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = plx::testing::MakeTempDir("plx_map_snapshot"); }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string File(const std::string& name) const { return dir_ + "/" + name + ".plx"; }
  // The version number and keyframes the map's file holds.
  MapFileInfo FileInfo(const std::string& name) const {
    absl::StatusOr<MapFileInfo> info = ReadMapInfo(File(name));
    EXPECT_TRUE(info.ok()) << info.status();
    return info.ok() ? *info : MapFileInfo();
  }
  std::vector<std::string> TempFiles() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) {
      if (e.path().string().find(".tmp.") != std::string::npos) names.push_back(e.path());
    }
    return names;
  }
  std::string dir_;
};

TEST_F(MapStoreSnapshotTest, KeyframesAndTheVersionNumberComeBackAtTheNextStart) {
  const std::shared_ptr<const MapKeyframes> keyframes = Keyframes(5);
  {
    MapStore store(InDir(dir_));
    ASSERT_TRUE(store.Create("room", kVoxel).ok());
    ASSERT_TRUE(store.Publish("room", MapWithBricks(2), 3, Keyframes(3)).ok());
    ASSERT_TRUE(store.Publish("room", MapWithBricks(3), 2, keyframes).ok());
    EXPECT_EQ(store.Info("room")->keyframes, 5);  // the list's size, not a running sum
    ASSERT_TRUE(store.Save("room").ok());
  }
  MapStore restarted(InDir(dir_));
  EXPECT_THAT(restarted.LoadAllFromDataDir(), IsEmpty());
  const MapStatus room = *restarted.Info("room");
  EXPECT_EQ(room.keyframes, 5);
  EXPECT_EQ(room.version, 3u) << "the number it was saved at";
  EXPECT_FALSE(room.dirty);
  const MapVersion latest = *restarted.Latest("room");
  ASSERT_NE(latest.keyframes, nullptr);
  ASSERT_EQ(latest.keyframes->size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    const MapKeyframe& a = (*keyframes)[i];
    const MapKeyframe& b = (*latest.keyframes)[i];
    EXPECT_EQ(a.timestamp, b.timestamp);
    EXPECT_EQ(a.pose.translation(), b.pose.translation());
    ASSERT_EQ(a.features == nullptr, b.features == nullptr);
    if (a.features != nullptr) {
      EXPECT_EQ(a.features->descriptors, b.features->descriptors);
    }
  }
  // The numbers go on from there.
  EXPECT_EQ(restarted.Publish("room", MapWithBricks(1), 0, nullptr).value_or(0), 4u);
  EXPECT_EQ(restarted.Info("room")->keyframes, 5) << "no list given: the old one stays";
}

TEST_F(MapStoreSnapshotTest, ADueMapIsClaimedOnceAndItsNewestVersionWritten) {
  MapStore store(InDir(dir_));
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Create("clean", kVoxel).ok());
  const absl::Time changed = absl::Now();
  ASSERT_TRUE(store.Publish("room", MapWithBricks(2), 2, Keyframes(2)).ok());
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, changed + absl::Seconds(29)), IsEmpty());
  const absl::Time next = store.NextSnapshotDue(kInterval);
  EXPECT_GE(next, changed + kInterval);
  EXPECT_LT(next, changed + kInterval + absl::Seconds(5));
  ASSERT_TRUE(store.Publish("room", MapWithBricks(3), 1, Keyframes(3)).ok());  // version 3
  const absl::Time later = absl::Now() + kInterval + absl::Seconds(1);
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, later), ElementsAre("room"));
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, later), IsEmpty()) << "claimed already";
  EXPECT_EQ(store.NextSnapshotDue(kInterval), absl::InfiniteFuture());

  const absl::StatusOr<SaveOutcome> saved = store.Snapshot("room", kInterval);
  ASSERT_TRUE(saved.ok()) << saved.status();
  EXPECT_FALSE(saved->skipped);
  EXPECT_EQ(saved->version, 3u);
  EXPECT_EQ(saved->keyframes, 3);
  EXPECT_EQ(saved->bytes, static_cast<int64_t>(fs::file_size(File("room"))));
  EXPECT_EQ(FileInfo("room").map_version, 3u);
  EXPECT_EQ(FileInfo("room").keyframes, 3);
  EXPECT_FALSE(store.Info("room")->dirty);
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, later + absl::Hours(1)), IsEmpty());
  EXPECT_FALSE(fs::exists(File("clean"))) << "a map without changes is never snapshot";
  EXPECT_THAT(TempFiles(), IsEmpty());
}

TEST_F(MapStoreSnapshotTest, ChangesPublishedDuringASnapshotKeepTheMapDirty) {
  // Every save sleeps 300 ms first (a slow disk): the version it writes is the one taken at its
  // start, and the mapping job publishes meanwhile without waiting for it.
  MapStore store(InDir(dir_, absl::Milliseconds(300)));
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(2), 2, Keyframes(2)).ok());  // version 2
  ASSERT_THAT(store.ClaimDueSnapshots(kInterval, absl::Now() + absl::Hours(1)),
              ElementsAre("room"));
  absl::StatusOr<SaveOutcome> saved;
  std::thread snapshot([&] { saved = store.Snapshot("room", kInterval); });
  absl::SleepFor(absl::Milliseconds(100));
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(store.Publish("room", MapWithBricks(4), 2, Keyframes(4)).ok());  // version 3
  const double publish_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const absl::Time changed_during = absl::Now();
  snapshot.join();
  ASSERT_TRUE(saved.ok()) << saved.status();
  EXPECT_LT(publish_s, 0.1) << "a publish never waits for a snapshot";
  EXPECT_EQ(saved->version, 2u);
  EXPECT_EQ(FileInfo("room").map_version, 2u);
  EXPECT_EQ(FileInfo("room").keyframes, 2);
  const MapStatus room = *store.Info("room");
  EXPECT_TRUE(room.dirty) << "version 3 is not in the file";
  // Due an interval after that change (not after the snapshot's start), less what the save
  // took (at least the 300 ms it slept), so the next file holds it an interval after it.
  const absl::Time next = store.NextSnapshotDue(kInterval);
  EXPECT_LE(next, changed_during + kInterval - absl::Milliseconds(250));
  EXPECT_GE(next, changed_during + kInterval - absl::Seconds(2));
}

TEST_F(MapStoreSnapshotTest, ASaveWaitsForTheRunningSnapshotAndMakesAQueuedOnePointless) {
  MapStore store(InDir(dir_, absl::Milliseconds(300)));
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(2), 2, Keyframes(2)).ok());
  ASSERT_THAT(store.ClaimDueSnapshots(kInterval, absl::Now() + absl::Hours(1)),
              ElementsAre("room"));
  absl::StatusOr<SaveOutcome> first;
  std::thread snapshot([&] { first = store.Snapshot("room", kInterval); });
  absl::SleepFor(absl::Milliseconds(100));
  ASSERT_TRUE(store.Publish("room", MapWithBricks(3), 1, Keyframes(3)).ok());  // version 3
  // Both write room.plx: the save waits for the snapshot instead of sharing its temporary.
  const absl::StatusOr<MapStatus> saved = store.Save("room");
  snapshot.join();
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(saved.ok()) << saved.status();
  EXPECT_EQ(first->version, 2u);
  EXPECT_FALSE(saved->dirty);
  EXPECT_EQ(FileInfo("room").map_version, 3u) << "the later save's version is the file's";
  EXPECT_THAT(TempFiles(), IsEmpty());

  // A snapshot claimed before a save that left nothing unsaved writes nothing.
  ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 0, Keyframes(3)).ok());  // version 4
  ASSERT_THAT(store.ClaimDueSnapshots(kInterval, absl::Now() + absl::Hours(1)),
              ElementsAre("room"));
  ASSERT_TRUE(store.Save("room").ok());
  const absl::StatusOr<SaveOutcome> pointless = store.Snapshot("room", kInterval);
  ASSERT_TRUE(pointless.ok()) << pointless.status();
  EXPECT_TRUE(pointless->skipped);
  EXPECT_EQ(FileInfo("room").map_version, 4u);
}

TEST_F(MapStoreSnapshotTest, AFailedSnapshotLeavesTheMapDirtyAndIsRetriedAnIntervalLater) {
  const std::string gone = dir_ + "/gone";
  fs::create_directories(gone);
  MapStore store(InDir(gone));
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 1, Keyframes(1)).ok());
  fs::remove_all(gone);  // the data dir vanished (an unmounted volume)
  ASSERT_THAT(store.ClaimDueSnapshots(kInterval, absl::Now() + absl::Hours(1)),
              ElementsAre("room"));
  const absl::Time failed_at = absl::Now();
  const absl::StatusOr<SaveOutcome> failed = store.Snapshot("room", kInterval);
  EXPECT_EQ(failed.status().code(), absl::StatusCode::kNotFound) << failed.status();
  EXPECT_TRUE(store.Info("room")->dirty);
  EXPECT_GE(store.NextSnapshotDue(kInterval), failed_at + kInterval);
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, failed_at + absl::Seconds(29)), IsEmpty());
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, absl::Now() + kInterval + absl::Seconds(1)),
              ElementsAre("room"));
  // The volume is back: the retry saves it.
  fs::create_directories(gone);
  const absl::StatusOr<SaveOutcome> retried = store.Snapshot("room", kInterval);
  ASSERT_TRUE(retried.ok()) << retried.status();
  EXPECT_FALSE(store.Info("room")->dirty);
}

TEST_F(MapStoreSnapshotTest, AReleasedClaimIsClaimedAgain) {
  MapStore store(InDir(dir_));
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 1, Keyframes(1)).ok());
  const absl::Time later = absl::Now() + absl::Hours(1);
  ASSERT_THAT(store.ClaimDueSnapshots(kInterval, later), ElementsAre("room"));
  store.ReleaseSnapshot("room");
  EXPECT_THAT(store.ClaimDueSnapshots(kInterval, later), ElementsAre("room"));
  // Without a data dir nothing is ever claimed.
  MapStore nowhere((MapStoreOptions()));
  ASSERT_TRUE(nowhere.Create("room", kVoxel).ok());
  ASSERT_TRUE(nowhere.Publish("room", MapWithBricks(1), 1).ok());
  EXPECT_THAT(nowhere.ClaimDueSnapshots(kInterval, later), IsEmpty());
  EXPECT_EQ(nowhere.NextSnapshotDue(kInterval), absl::InfiniteFuture());
}

}  // namespace
}  // namespace plx::server

// The daemon's maps without a daemon: create/list/delete and their checks, published versions
// (readers keep theirs; stale occupancy and maps over the byte limit are refused), the one
// writer lease per map, and the data directory (save, load, what a delete removes).
#include "server/map_store.h"

#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/cpu/cpu_backend.h"
#include "core/kernels/refresh_occupancy.h"
#include "tests/server/published_map.h"
#include "tests/test_util.h"

namespace plx::server {
namespace map_store_test {

using ::testing::AllOf;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::Not;

constexpr float kVoxel = 0.05f;

// A map as a mapping job publishes it (tests/server/published_map.h), at this file's voxel size.
std::shared_ptr<const PlenoxelMap> MapWithBricks(int bricks, bool refresh = true) {
  return testing::MapWithBricks(kVoxel, bricks, refresh);
}

int64_t BytesOf(const PlenoxelMap& map) { return map.grid.Memory().total_bytes(); }

std::vector<std::string> Names(const std::vector<MapStatus>& maps) {
  std::vector<std::string> names;
  for (const MapStatus& m : maps) names.push_back(m.name);
  return names;
}

MapStoreOptions InDir(const std::string& dir) {
  MapStoreOptions options;
  options.data_dir = dir;
  return options;
}

// The one-writer lease remembers what holds it, so a client told that a map is busy learns what
// to stop: a Slam stream's SLAM job, or an Integrate stream.
TEST(MapStoreTest, DeletingAMapBeingMappedNamesWhatMapsIt) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("room", 0.05f).ok());

  ASSERT_TRUE(store.BeginMapping("room", MappingJobKind::kSlam).ok());
  const absl::Status slam = store.Delete("room");
  EXPECT_EQ(slam.code(), absl::StatusCode::kFailedPrecondition) << slam;
  EXPECT_THAT(slam.message(),
              AllOf(HasSubstr("map \"room\" is being mapped by its SLAM job"),
                    HasSubstr("end its Slam streams first"), Not(HasSubstr("Integrate"))));
  const absl::Status second = store.BeginMapping("room", MappingJobKind::kIntegrate);
  EXPECT_EQ(second.code(), absl::StatusCode::kFailedPrecondition) << second;
  EXPECT_THAT(second.message(), HasSubstr("already has a mapping job, its SLAM job"));
  store.EndMapping("room");

  ASSERT_TRUE(store.BeginMapping("room", MappingJobKind::kIntegrate).ok());
  const absl::Status integrate = store.Delete("room");
  EXPECT_EQ(integrate.code(), absl::StatusCode::kFailedPrecondition) << integrate;
  EXPECT_THAT(integrate.message(),
              AllOf(HasSubstr("map \"room\" is being mapped by an Integrate stream"),
                    Not(HasSubstr("SLAM"))));
  store.EndMapping("room");

  EXPECT_TRUE(store.Delete("room").ok());
}

TEST(MapStoreTest, CreateGetListAndDelete) {
  MapStore store(MapStoreOptions{});
  absl::StatusOr<MapStatus> created = store.Create("kitchen", kVoxel);
  ASSERT_TRUE(created.ok()) << created.status();
  EXPECT_EQ(created->name, "kitchen");
  EXPECT_FLOAT_EQ(created->voxel_size, kVoxel);
  EXPECT_EQ(created->version, 1u);
  EXPECT_EQ(created->bricks, 0);
  EXPECT_EQ(created->keyframes, 0);
  EXPECT_FALSE(created->dirty);
  EXPECT_FALSE(created->mapping);
  ASSERT_TRUE(store.Create("bathroom", 0.1f).ok());

  absl::StatusOr<MapStatus> info = store.Info("kitchen");
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version, created->version);
  EXPECT_FLOAT_EQ(info->voxel_size, kVoxel);
  EXPECT_THAT(Names(store.List()), ElementsAre("bathroom", "kitchen"));  // by name
  EXPECT_EQ(store.size(), 2);
  absl::StatusOr<MapVersion> latest = store.Latest("kitchen");
  ASSERT_TRUE(latest.ok());
  EXPECT_EQ(latest->version, 1u);
  EXPECT_EQ(latest->map->grid.num_bricks(), 0);
  EXPECT_FALSE(latest->map->grid.occupancy_stale()) << "a published version must be exact";

  ASSERT_TRUE(store.Delete("kitchen").ok());
  EXPECT_EQ(store.Info("kitchen").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store.Latest("kitchen").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store.Delete("kitchen").code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store.BeginMapping("kitchen", MappingJobKind::kIntegrate).code(),
            absl::StatusCode::kNotFound);
  EXPECT_THAT(Names(store.List()), ElementsAre("bathroom"));
  // The name is free again, for a new map.
  created = store.Create("kitchen", 0.2f);
  ASSERT_TRUE(created.ok());
  EXPECT_FLOAT_EQ(created->voxel_size, 0.2f);
}

TEST(MapStoreTest, CreateChecksTheNameAndTheVoxelSize) {
  MapStore store(MapStoreOptions{});
  for (const std::string& name : {std::string(), std::string(".hidden"), std::string("a/b"),
                                  std::string("with space"), std::string(65, 'x')}) {
    const absl::Status s = store.Create(name, kVoxel).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << "\"" << name << "\"";
    EXPECT_THAT(s.message(), HasSubstr("name")) << s;
  }
  for (float voxel : {0.0f, 0.0009f, 1.01f, -0.1f, std::nanf(""), INFINITY}) {
    const absl::Status s = store.Create("v", voxel).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << voxel;
    EXPECT_THAT(s.message(), HasSubstr("voxel_size")) << s;
  }
  EXPECT_EQ(store.size(), 0);
  // The ends of the range and of the name length are allowed.
  EXPECT_TRUE(store.Create("fine", 0.001f).ok());
  EXPECT_TRUE(store.Create(std::string(64, 'y'), 1.0f).ok());

  const absl::Status twin = store.Create("fine", 0.5f).status();
  EXPECT_EQ(twin.code(), absl::StatusCode::kAlreadyExists) << twin;
  EXPECT_FLOAT_EQ(store.Info("fine")->voxel_size, 0.001f) << "the original is untouched";
}

TEST(MapStoreTest, MaxMapsIsResourceExhaustedUntilOneIsDeleted) {
  MapStoreOptions options;
  options.max_maps = 2;
  MapStore store(options);
  ASSERT_TRUE(store.Create("a", kVoxel).ok());
  ASSERT_TRUE(store.Create("b", kVoxel).ok());
  const absl::Status full = store.Create("c", kVoxel).status();
  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted) << full;
  EXPECT_THAT(full.message(), HasSubstr("maximum of 2 maps"));
  ASSERT_TRUE(store.Delete("a").ok());
  EXPECT_TRUE(store.Create("c", kVoxel).ok());
  EXPECT_THAT(Names(store.List()), ElementsAre("b", "c"));
}

// Readers hold a version as long as they like: publishing replaces the store's, never theirs.
TEST(MapStoreTest, PublishingMakesANewVersionAndReadersKeepTheirs) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  const MapVersion before = *store.Latest("room");

  const std::shared_ptr<const PlenoxelMap> three = MapWithBricks(3);
  absl::StatusOr<uint64_t> version = store.Publish("room", three, 2);
  ASSERT_TRUE(version.ok()) << version.status();
  EXPECT_EQ(*version, 2u);
  const MapVersion after = *store.Latest("room");
  EXPECT_EQ(after.version, 2u);
  EXPECT_EQ(after.map, three);
  EXPECT_EQ(before.version, 1u);
  EXPECT_EQ(before.map->grid.num_bricks(), 0);

  MapStatus info = *store.Info("room");
  EXPECT_EQ(info.version, 2u);
  EXPECT_EQ(info.bricks, 3);
  EXPECT_EQ(info.memory_bytes, BytesOf(*three));
  EXPECT_EQ(info.keyframes, 2);
  EXPECT_TRUE(info.dirty);
  EXPECT_THAT(store.DirtyNames(), ElementsAre("room"));

  // Keyframes add up over versions.
  ASSERT_EQ(store.Publish("room", MapWithBricks(4), 1).value_or(0), 3u);
  info = *store.Info("room");
  EXPECT_EQ(info.keyframes, 3);
  EXPECT_EQ(info.bricks, 4);
  EXPECT_EQ(store.Publish("nope", MapWithBricks(1), 1).status().code(),
            absl::StatusCode::kNotFound);
}

// Concurrent readers would each refresh a stale map's occupancy in place: such a version is a
// bug in the writer, refused before the store changes.
TEST(MapStoreTest, AVersionWithStaleOccupancyIsRefused) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  const std::shared_ptr<const PlenoxelMap> stale = MapWithBricks(2, /*refresh=*/false);
  ASSERT_TRUE(stale->grid.occupancy_stale());
  const absl::Status s = store.Publish("room", stale, 1).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInternal) << s;
  EXPECT_THAT(s.message(), HasSubstr("stale occupancy"));
  const MapStatus info = *store.Info("room");
  EXPECT_EQ(info.version, 1u);
  EXPECT_EQ(info.bricks, 0);
  EXPECT_EQ(info.keyframes, 0);
  EXPECT_FALSE(info.dirty);
}

TEST(MapStoreTest, AVersionOverTheByteLimitIsRefusedAndThePreviousOneStays) {
  const std::shared_ptr<const PlenoxelMap> two = MapWithBricks(2);
  const std::shared_ptr<const PlenoxelMap> three = MapWithBricks(3);
  ASSERT_LT(BytesOf(*two), BytesOf(*three));
  MapStoreOptions options;
  options.max_map_bytes = BytesOf(*two);  // exactly at the limit is allowed
  MapStore store(options);
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", two, 1).ok());

  const absl::Status s = store.Publish("room", three, 1).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_THAT(s.message(), AllOf(HasSubstr("map \"room\""), HasSubstr("over the limit")));
  const MapVersion latest = *store.Latest("room");
  EXPECT_EQ(latest.version, 2u);
  EXPECT_EQ(latest.map, two);
  EXPECT_EQ(store.Info("room")->keyframes, 1);
}

TEST(MapStoreTest, TotalBytesIsTheSumOfTheLatestVersions) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("a", kVoxel).ok());
  ASSERT_TRUE(store.Create("b", kVoxel).ok());
  const int64_t empty = store.Info("a")->memory_bytes;
  EXPECT_EQ(store.TotalBytes(), 2 * empty);

  const std::shared_ptr<const PlenoxelMap> two = MapWithBricks(2);
  const std::shared_ptr<const PlenoxelMap> five = MapWithBricks(5);
  ASSERT_TRUE(store.Publish("a", two, 1).ok());
  ASSERT_TRUE(store.Publish("b", five, 1).ok());
  EXPECT_EQ(store.TotalBytes(), BytesOf(*two) + BytesOf(*five));
  // A replaced version no longer counts, though a reader may still hold it.
  const MapVersion held = *store.Latest("b");
  ASSERT_TRUE(store.Publish("b", two, 1).ok());
  EXPECT_EQ(store.TotalBytes(), 2 * BytesOf(*two));
  ASSERT_TRUE(store.Delete("a").ok());
  EXPECT_EQ(store.TotalBytes(), BytesOf(*two));
  EXPECT_EQ(held.map->grid.num_bricks(), 5);
}

TEST(MapStoreTest, TheMappingLeaseIsOnePerMapAndShows) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("a", kVoxel).ok());
  ASSERT_TRUE(store.Create("b", kVoxel).ok());
  ASSERT_TRUE(store.BeginMapping("a", MappingJobKind::kIntegrate).ok());
  EXPECT_TRUE(store.Info("a")->mapping);
  EXPECT_FALSE(store.Info("b")->mapping);
  // Another map has its own lease.
  EXPECT_TRUE(store.BeginMapping("b", MappingJobKind::kSlam).ok());
  const absl::Status again = store.BeginMapping("a", MappingJobKind::kIntegrate);
  EXPECT_EQ(again.code(), absl::StatusCode::kFailedPrecondition) << again;
  EXPECT_THAT(again.message(), HasSubstr("an Integrate stream (one writer per map)"));

  // The holder publishes; the lease stays until it ends.
  ASSERT_TRUE(store.Publish("a", MapWithBricks(1), 1).ok());
  EXPECT_TRUE(store.Info("a")->mapping);
  store.EndMapping("a");
  EXPECT_FALSE(store.Info("a")->mapping);
  EXPECT_TRUE(store.Info("b")->mapping);
  store.EndMapping("nope");  // an unknown map (deleted meanwhile): nothing happens
  EXPECT_TRUE(store.BeginMapping("a", MappingJobKind::kSlam).ok());
}

TEST(MapStoreTest, WithoutADataDirNothingIsSavedOrLoaded) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 1).ok());
  EXPECT_EQ(store.Save("room").status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(store.Load("room").status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(store.LoadAllFromDataDir(), IsEmpty());
  EXPECT_THAT(store.RemoveStaleTempFiles(), IsEmpty());
  // The drain reports the map it could not save.
  const std::vector<UnsavedMap> unsaved = store.SaveDirty();
  ASSERT_EQ(unsaved.size(), 1u);
  EXPECT_EQ(unsaved[0].name, "room");
  EXPECT_EQ(unsaved[0].reason.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(store.Info("room")->dirty);
}

TEST(MapStoreTest, SavedMapsComeBackAtTheNextStartAndLoadReplacesTheMap) {
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  const std::shared_ptr<const PlenoxelMap> three = MapWithBricks(3);
  {
    MapStore store(InDir(dir));
    ASSERT_TRUE(store.Create("room", kVoxel).ok());
    ASSERT_TRUE(store.Create("hall", 0.1f).ok());
    ASSERT_TRUE(store.Publish("room", three, 4).ok());
    absl::StatusOr<MapStatus> saved = store.Save("room");
    ASSERT_TRUE(saved.ok()) << saved.status();
    EXPECT_FALSE(saved->dirty);
    EXPECT_EQ(saved->version, 2u);
    EXPECT_THAT(store.DirtyNames(), IsEmpty());
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / "room.plx"));
    EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(dir) / "hall.plx"))
        << "only what was saved";

    // Loading over the map in memory replaces it with the file's, as a new version.
    ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 1).ok());
    absl::StatusOr<MapStatus> loaded = store.Load("room");
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    EXPECT_EQ(loaded->version, 4u);
    EXPECT_EQ(loaded->bricks, 3);
    EXPECT_FALSE(loaded->dirty);

    EXPECT_EQ(store.Load("attic").status().code(), absl::StatusCode::kNotFound);
    EXPECT_EQ(store.Load("../room").status().code(), absl::StatusCode::kInvalidArgument);
    ASSERT_TRUE(store.BeginMapping("room", MappingJobKind::kIntegrate).ok());
    const absl::Status busy = store.Load("room").status();
    EXPECT_EQ(busy.code(), absl::StatusCode::kFailedPrecondition) << busy;
    EXPECT_THAT(busy.message(), HasSubstr("is being mapped"));
  }
  MapStore restarted(InDir(dir));
  EXPECT_THAT(restarted.LoadAllFromDataDir(), IsEmpty());
  EXPECT_THAT(Names(restarted.List()), ElementsAre("room"));
  const MapStatus room = *restarted.Info("room");
  EXPECT_EQ(room.bricks, 3);
  EXPECT_FLOAT_EQ(room.voxel_size, kVoxel);
  EXPECT_EQ(room.memory_bytes, BytesOf(*three));
  EXPECT_FALSE(room.dirty);
  EXPECT_FALSE(restarted.Latest("room")->map->grid.occupancy_stale());
  std::filesystem::remove_all(dir);
}

// What cannot be loaded at the start is reported and skipped; it never stops the other maps.
TEST(MapStoreTest, LoadingTheDataDirSkipsAndReportsWhatIsNotAMap) {
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  {
    MapStore store(InDir(dir));
    ASSERT_TRUE(store.Create("good", kVoxel).ok());
    ASSERT_TRUE(store.Save("good").ok());
  }
  const std::filesystem::path d(dir);
  std::ofstream(d / "corrupt.plx") << "not a map";
  std::filesystem::copy_file(d / "good.plx", d / "bad name.plx");
  std::ofstream(d / "notes.txt") << "not .plx: ignored";
  ASSERT_EQ(::mkfifo((d / "pipe.plx").c_str(), 0600), 0);

  MapStore store(InDir(dir));
  const std::vector<std::string> problems = store.LoadAllFromDataDir();
  EXPECT_EQ(problems.size(), 3u);
  EXPECT_THAT(problems, ::testing::Contains(HasSubstr("corrupt.plx")));
  EXPECT_THAT(problems, ::testing::Contains(HasSubstr("not a valid map name")));
  EXPECT_THAT(problems, ::testing::Contains(HasSubstr("not a regular file")));
  EXPECT_THAT(Names(store.List()), ElementsAre("good"));
  std::filesystem::remove_all(dir);
}

TEST(MapStoreTest, LoadRefusesWhenTheStoreIsFullOrTheMapTooLarge) {
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  const std::shared_ptr<const PlenoxelMap> three = MapWithBricks(3);
  {
    MapStore store(InDir(dir));
    ASSERT_TRUE(store.Create("big", kVoxel).ok());
    ASSERT_TRUE(store.Publish("big", three, 1).ok());
    ASSERT_TRUE(store.Save("big").ok());
  }
  MapStoreOptions one = InDir(dir);
  one.max_maps = 1;
  MapStore full(one);
  ASSERT_TRUE(full.Create("other", kVoxel).ok());
  EXPECT_EQ(full.Load("big").status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(Names(full.List()), ElementsAre("other"));

  // The header's estimate is a lower bound of the loaded map's bytes: a limit a brick smaller.
  MapStoreOptions small = InDir(dir);
  small.max_map_bytes = BytesOf(*MapWithBricks(2));
  MapStore tight(small);
  const absl::Status s = tight.Load("big").status();
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_EQ(tight.size(), 0);
  EXPECT_THAT(tight.LoadAllFromDataDir(), ElementsAre(HasSubstr("big.plx")));
  EXPECT_EQ(tight.size(), 0);
  small.max_map_bytes = BytesOf(*three);
  MapStore enough(small);
  EXPECT_TRUE(enough.Load("big").ok());
  std::filesystem::remove_all(dir);
}

// Delete removes the file the store read or wrote, and no other; when that fails the map stays,
// or it would come back at the next start after an OK.
TEST(MapStoreTest, DeleteRemovesOnlyTheStoresOwnFileAndKeepsTheMapWhenItCannot) {
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  const std::filesystem::path d(dir);
  MapStore store(InDir(dir));
  ASSERT_TRUE(store.Create("saved", kVoxel).ok());
  ASSERT_TRUE(store.Save("saved").ok());
  ASSERT_TRUE(store.Create("fresh", kVoxel).ok());
  std::filesystem::copy_file(d / "saved.plx", d / "fresh.plx");  // not the store's file

  ASSERT_TRUE(store.Delete("fresh").ok());
  EXPECT_TRUE(std::filesystem::exists(d / "fresh.plx"));

  // A non-empty directory took the saved map's place: it cannot be removed.
  std::filesystem::remove(d / "saved.plx");
  std::filesystem::create_directory(d / "saved.plx");
  std::ofstream(d / "saved.plx" / "x") << "x";
  const absl::Status s = store.Delete("saved");
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr("was not deleted"));
  EXPECT_TRUE(store.Info("saved").ok());
  std::filesystem::remove_all(d / "saved.plx");
  EXPECT_TRUE(store.Delete("saved").ok()) << "a file already gone is no error";
  EXPECT_FALSE(store.Info("saved").ok());
  std::filesystem::remove_all(dir);
}

// Saves run outside the store's lock (test_only_save_delay holds one in the middle): a version
// published meanwhile is not in the file, so the map stays dirty; a map deleted meanwhile must
// not come back from the file at the next start (the delete waits for the save writing its
// file, one operation on a map's file at a time, then removes it), and the save still answers
// with the map as it saved it (taken before the delete's turn, not looked up after it). The
// save thread is given kSaveStarts to begin before the main thread acts, and the save is held
// three times that, so a loaded 2-core machine still runs them in that order.
TEST(MapStoreTest, WhatHappensDuringASaveIsNotLost) {
  constexpr auto kSaveStarts = std::chrono::milliseconds(400);
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  MapStoreOptions options = InDir(dir);
  options.test_only_save_delay = absl::FromChrono(3 * kSaveStarts);
  MapStore store(options);
  ASSERT_TRUE(store.Create("room", kVoxel).ok());
  ASSERT_TRUE(store.Publish("room", MapWithBricks(1), 1).ok());
  absl::StatusOr<MapStatus> saved;
  std::thread save([&] { saved = store.Save("room"); });
  std::this_thread::sleep_for(kSaveStarts);
  ASSERT_TRUE(store.Publish("room", MapWithBricks(2), 1).ok());
  save.join();
  ASSERT_TRUE(saved.ok()) << saved.status();
  EXPECT_TRUE(saved->dirty);
  EXPECT_THAT(store.DirtyNames(), ElementsAre("room"));

  ASSERT_TRUE(store.Create("gone", kVoxel).ok());
  save = std::thread([&] { saved = store.Save("gone"); });
  std::this_thread::sleep_for(kSaveStarts);
  const auto delete_start = std::chrono::steady_clock::now();
  ASSERT_TRUE(store.Delete("gone").ok());
  EXPECT_GT(std::chrono::steady_clock::now() - delete_start, kSaveStarts)
      << "the delete waited for the save";
  save.join();
  EXPECT_TRUE(saved.ok()) << saved.status();
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(dir) / "gone.plx"));
  std::filesystem::remove_all(dir);
}

// The drain saves every dirty map it can and names the others with the reason.
TEST(MapStoreTest, SaveDirtyTriesEveryMap) {
  const std::string dir = plx::testing::MakeTempDir("plx_map_store");
  MapStore store(InDir(dir));
  for (const char* name : {"a", "blocked", "c", "clean"}) {
    ASSERT_TRUE(store.Create(name, kVoxel).ok());
  }
  for (const char* name : {"a", "blocked", "c"}) {
    ASSERT_TRUE(store.Publish(name, MapWithBricks(1), 1).ok());
  }
  std::filesystem::create_directory(std::filesystem::path(dir) / "blocked.plx");
  std::ofstream(std::filesystem::path(dir) / "blocked.plx" / "x") << "x";

  const std::vector<UnsavedMap> unsaved = store.SaveDirty();
  ASSERT_EQ(unsaved.size(), 1u);
  EXPECT_EQ(unsaved[0].name, "blocked");
  EXPECT_FALSE(unsaved[0].reason.ok());
  EXPECT_THAT(store.DirtyNames(), ElementsAre("blocked"));
  EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / "a.plx"));
  EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / "c.plx"));
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(dir) / "clean.plx"));
  std::filesystem::remove_all(dir);
}

}  // namespace map_store_test
}  // namespace plx::server

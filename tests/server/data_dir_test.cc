// The daemon's data directory holds whatever was put there: files that are not maps must never
// block the daemon, and what the daemon itself leaves behind (temporaries of interrupted
// saves, deleted maps) is cleaned up.
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "tests/fifo_valve.h"
#include "tests/server/daemon_fixture.h"
#include "tests/server/daemon_process.h"

namespace plx::server::testing {
namespace {

namespace fs = std::filesystem;

grpc::Status LoadMapCall(pb::Plenoxd::Stub& stub, const std::string& name,
                         pb::MapInfo* info = nullptr) {
  grpc::ClientContext context;
  Prepare(&context, "", absl::Seconds(20));
  pb::LoadMapRequest request;
  request.set_name(name);
  pb::MapInfo response;
  const grpc::Status s = stub.LoadMap(&context, request, &response);
  if (info != nullptr) *info = response;
  return s;
}

// Temporaries of saves that a crash interrupted ("<name>.plx.tmp.<pid>" of a pid that is gone)
// are removed when the daemon starts, and each removal is logged; a temporary of a running
// process (maybe a save in progress) and other files stay.
TEST(DataDirTest, StaleTemporariesAreRemovedAtStart) {
  const std::string data = plx::testing::MakeTempDir("plx_srv_stale");
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ::waitpid(child, nullptr, 0);  // a pid that no process has now
  const std::string stale = absl::StrCat(data, "/room.plx.tmp.", child);
  const std::string live = absl::StrCat(data, "/other.plx.tmp.", ::getpid());
  const std::string unrelated = absl::StrCat(data, "/notes.txt.tmp.", child);
  for (const std::string& path : {stale, live, unrelated}) {
    std::ofstream(path) << "half a map";
  }
  ::testing::internal::CaptureStderr();
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(TestDaemonOptions(data));
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(started.ok()) << started.status();
  EXPECT_FALSE(fs::exists(stale));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_TRUE(fs::exists(unrelated));
  EXPECT_NE(log.find("event=stale_temp_removed path=" + stale), std::string::npos) << log;
}

// DeleteMap removes the file the daemon loaded the map from or saved it to, and no other; when
// that fails, the map stays and the call says why (it used to answer OK, and the map came back
// at the next start).
TEST(DataDirTest, DeleteMapRemovesOnlyItsOwnFileAndReportsFailure) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  const auto delete_map = [&](const std::string& name) {
    grpc::ClientContext context;
    Prepare(&context);
    pb::DeleteMapRequest request;
    request.set_name(name);
    pb::DeleteMapResponse response;
    return d.stub->DeleteMap(&context, request, &response);
  };

  // A file put into the data dir after the start is not the in-memory map's.
  ASSERT_TRUE(CreateMap(*d.stub, "fresh").ok());
  const std::string foreign = d.data_dir + "/fresh.plx";
  std::ofstream(foreign) << "someone else's";
  const grpc::Status deleted = delete_map("fresh");
  EXPECT_TRUE(deleted.ok()) << Describe(deleted);
  EXPECT_TRUE(fs::exists(foreign));

  // The loaded map's file cannot be removed (a non-empty directory took its place).
  const std::string own = d.data_dir + "/room.plx";
  ASSERT_TRUE(fs::remove(own));
  fs::create_directories(own + "/inside");
  const grpc::Status failed = delete_map("room");
  EXPECT_FALSE(failed.ok());
  EXPECT_NE(failed.error_message().find("room.plx"), std::string::npos) << Describe(failed);
  pb::MapInfo info;
  EXPECT_TRUE(GetMap(*d.stub, "room", &info).ok()) << "the map was dropped though its file stays";

  // Once removable, deleting it removes it.
  fs::remove_all(own);
  ASSERT_TRUE(SaveMap(*d.stub, "room").ok());
  ASSERT_TRUE(fs::exists(own));
  const grpc::Status now = delete_map("room");
  EXPECT_TRUE(now.ok()) << Describe(now);
  EXPECT_FALSE(fs::exists(own));
}

// A map file that is corrupt or cut short is DATA_LOSS (the API documents it for LoadMap):
// the bytes are there but are not a map any more, unlike a file that is not a map at all.
TEST(DataDirTest, ACorruptOrTruncatedMapFileIsDataLoss) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  std::string bytes;
  {
    std::ifstream in(d.data_dir + "/room.plx", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_GT(bytes.size(), 1000u);
  std::string flipped = bytes;
  flipped[flipped.size() / 2] ^= 0x40;  // in the payload: the checksum no longer matches
  std::ofstream(d.data_dir + "/flipped.plx", std::ios::binary) << flipped;
  std::ofstream(d.data_dir + "/cut.plx", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  for (const std::string name : {"flipped", "cut"}) {
    const grpc::Status s = LoadMapCall(*d.stub, name);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS) << name << ": " << Describe(s);
    EXPECT_NE(s.error_message().find(name + ".plx"), std::string::npos) << Describe(s);
  }
}

#ifdef PLENOXD_BINARY

// A FIFO named like a map used to block the daemon's start in open() (it never listened), and
// then every later load, save and SIGTERM. Now it is skipped at start, LoadMap of it fails at
// once, and the other maps load and save.
TEST(DataDirTest, AFifoNamedLikeAMapBlocksNothing) {
  const std::string dir = plx::testing::MakeTempDir("plx_srv_fifo");
  const std::string data = dir + "/data";
  fs::create_directories(data);
  SeedMaps(data, {"room"});
  const std::string fifo = data + "/pipe.plx";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0) << std::strerror(errno);
  // Releases a daemon stuck opening the FIFO after 10 s, so the test fails instead of hanging.
  plx::testing::FifoValve valve(fifo, plx::testing::FifoValve::Role::kWriter);

  DaemonProcess daemon(kPlenoxdBinary, dir, {"--data-dir", data, "--threads", "2"});
  const int port = daemon.WaitListening();
  ASSERT_GT(port, 0) << daemon.Log();
  EXPECT_FALSE(valve.released()) << "the daemon blocked on the FIFO at start\n" << daemon.Log();
  auto stub = pb::Plenoxd::NewStub(MakeChannel(port));

  const grpc::Status fifo_load = LoadMapCall(*stub, "pipe");
  EXPECT_FALSE(fifo_load.ok());
  EXPECT_NE(fifo_load.error_message().find("not a regular file"), std::string::npos)
      << Describe(fifo_load);
  EXPECT_FALSE(valve.released()) << "LoadMap blocked on the FIFO";

  pb::MapInfo room;
  const grpc::Status loaded = LoadMapCall(*stub, "room", &room);
  EXPECT_TRUE(loaded.ok()) << Describe(loaded);
  EXPECT_GT(room.bricks(), 0u);
  const grpc::Status saved = SaveMap(*stub, "room");
  EXPECT_TRUE(saved.ok()) << Describe(saved);

  const DaemonProcess::Exit exit = daemon.Stop(std::chrono::seconds(30));
  EXPECT_EQ(exit.code, 0) << daemon.Log();
  EXPECT_NE(daemon.Log().find("pipe.plx: not a regular file, skipped"), std::string::npos)
      << daemon.Log();
}

#endif  // PLENOXD_BINARY

}  // namespace
}  // namespace plx::server::testing

// The daemon's data directory holds whatever was put there: files that are not maps must never
// block the daemon, and what the daemon itself leaves behind (temporaries of interrupted
// saves, deleted maps) is cleaned up.
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
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

#ifdef PLENOXD_BINARY

// A FIFO named like a map used to block the daemon's start in open() (it never listened), and
// then every later load, save and SIGTERM. Now it is skipped at start, LoadMap of it fails at
// once, and the other maps load and save.
TEST(DataDirTest, AFifoNamedLikeAMapBlocksNothing) {
  const std::string dir = ScratchDir("plx_srv_fifo");
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

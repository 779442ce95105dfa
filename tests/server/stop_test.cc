// How plenoxd stops on SIGTERM, as a subprocess: it drains, saves what it can, and exits within
// --drain-seconds + --stop-grace-seconds (plus process start-up noise) whatever it gets stuck
// on; when a map could not be saved the exit status is non-zero and the log names the map.
// Under an address-space cap an out-of-memory stream once left SIGTERM hanging for good.
#include <chrono>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "server/stop_watchdog.h"
#include "tests/server/daemon_fixture.h"
#include "tests/server/daemon_process.h"

namespace plx::server::testing {
namespace {

namespace fs = std::filesystem;

#ifdef PLENOXD_BINARY

// Two maps changed since their last save.
void MakeDirtyMaps(pb::Plenoxd::Stub& stub, const std::vector<std::string>& names) {
  pb::IntegrateOptions quick;
  quick.set_iterations_per_keyframe(5);
  quick.set_rays_per_iteration(1024);
  for (const std::string& name : names) {
    ASSERT_TRUE(CreateMap(stub, name).ok());
    const IntegrateResult r = Integrate(stub, name, {0}, quick);
    ASSERT_TRUE(r.status.ok()) << Describe(r.status);
    pb::MapInfo info;
    ASSERT_TRUE(GetMap(stub, name, &info).ok());
    ASSERT_TRUE(info.dirty());
  }
}

// Saves that never finish (the test-only delay stands in for a hung file system): the watchdog
// ends the process at the deadline, exit 3, naming both maps.
TEST(StopTest, AStuckSaveStillEndsTheProcessInTimeNamingTheUnsavedMaps) {
  const std::string dir = plx::testing::MakeTempDir("plx_srv_stop_stuck");
  fs::create_directories(dir + "/data");
  DaemonProcess daemon(kPlenoxdBinary, dir,
                       {"--data-dir", dir + "/data", "--threads", "2", "--drain-seconds", "0.5",
                        "--stop-grace-seconds", "2"},
                       {"PLENOXD_TEST_ONLY_SAVE_DELAY_S=3600"});
  const int port = daemon.WaitListening();
  ASSERT_GT(port, 0) << daemon.Log();
  auto stub = pb::Plenoxd::NewStub(MakeChannel(port));
  MakeDirtyMaps(*stub, {"kitchen", "hall"});

  const DaemonProcess::Exit exit = daemon.Stop(std::chrono::seconds(60));
  const std::string log = daemon.Log();
  EXPECT_EQ(exit.code, kExitStopTimeout) << log;
  EXPECT_LT(exit.seconds, 0.5 + 2 + 5) << log;
  EXPECT_NE(log.find("event=stop_timeout"), std::string::npos) << log;
  EXPECT_NE(log.find("event=map_not_saved map=kitchen"), std::string::npos) << log;
  EXPECT_NE(log.find("event=map_not_saved map=hall"), std::string::npos) << log;
}

// One map cannot be saved (a directory stands where its file goes), the other can: the other
// is saved, the exit status is 1 and the log names the one lost.
TEST(StopTest, AMapThatCannotBeSavedIsNamedAndTheOthersAreSaved) {
  const std::string dir = plx::testing::MakeTempDir("plx_srv_stop_fail");
  const std::string data = dir + "/data";
  fs::create_directories(data);
  DaemonProcess daemon(kPlenoxdBinary, dir, {"--data-dir", data, "--threads", "2"});
  const int port = daemon.WaitListening();
  ASSERT_GT(port, 0) << daemon.Log();
  auto stub = pb::Plenoxd::NewStub(MakeChannel(port));
  MakeDirtyMaps(*stub, {"good", "bad"});
  fs::create_directories(data + "/bad.plx/occupied");

  const DaemonProcess::Exit exit = daemon.Stop(std::chrono::seconds(60));
  const std::string log = daemon.Log();
  EXPECT_EQ(exit.code, 1) << log;
  EXPECT_TRUE(fs::is_regular_file(data + "/good.plx")) << log;
  EXPECT_NE(log.find("event=map_not_saved map=bad"), std::string::npos) << log;
  EXPECT_EQ(log.find("event=map_not_saved map=good"), std::string::npos) << log;
}

#endif  // PLENOXD_BINARY

}  // namespace
}  // namespace plx::server::testing

// Shared map storage and its lease, end to end (issue 24, part 3): two real plenoxd processes on
// one --shared-dir. A makes a map and saves it; A is paused (SIGSTOP) with changes not yet
// saved; once A's lease has expired, B's call naming the map loads it (a generation higher)
// and B saves it; A is resumed (SIGCONT). A must write nothing: the file keeps B's bytes, and
// A's calls naming the map get FAILED_PRECONDITION naming the new generation. When B stops
// (and gives its lease up) A may load B's copy again.
#include <signal.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "core/formats/map_file.h"
#include "core/storage/directory_storage.h"
#include "tests/server/daemon_fixture.h"
#include "tests/server/daemon_process.h"

namespace plx::server::testing {
namespace {

namespace fs = std::filesystem;

constexpr double kLeaseSeconds = 2.0;

std::vector<std::string> SharedFlags(const std::string& shared_dir) {
  // Snapshots every 3 s: A's second batch of keyframes is still unsaved when A is paused
  // right after it, and overdue when A resumes.
  return {"--shared-dir", shared_dir, "--lease-seconds", absl::StrCat(kLeaseSeconds),
          "--snapshot-seconds", "3", "--threads", "2", "--metrics-port", "0"};
}

double MetricValue(int port, const std::string& name) {
  const std::string text = HttpGet(port, "/metrics");
  const std::string prefix = "\n" + name + " ";
  const size_t at = text.find(prefix);
  if (at == std::string::npos) return -1;
  double value = -1;
  const size_t start = at + prefix.size();
  const size_t end = text.find('\n', start);
  return absl::SimpleAtod(text.substr(start, end - start), &value) ? value : -1;
}

// What identifies one version of a file on disk: a rename puts a new inode in place.
struct FileIdentity {
  ino_t inode = 0;
  int64_t mtime_ns = 0;
  std::string bytes;
  bool operator==(const FileIdentity&) const = default;
};

FileIdentity Identify(const std::string& path) {
  FileIdentity id;
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return id;
  id.inode = st.st_ino;
  id.mtime_ns = int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
  id.bytes = ReadWholeFile(path);
  return id;
}

LeaseRecord ReadLease(const std::string& shared_dir, const std::string& map) {
  DirectoryMapStorage view(DirectoryStorageOptions{shared_dir, absl::Seconds(5), "test"});
  absl::StatusOr<LeaseRecord> lease = view.ReadLease(map);
  EXPECT_TRUE(lease.ok()) << lease.status();
  return lease.ok() ? *lease : LeaseRecord{};
}

TEST(SharedStorageTest, APausedOwnerThatLostItsLeaseWritesNothingWhenItResumes) {
  const std::string dir = plx::testing::MakeTempDir("plx_shared_storage");
  const std::string shared = dir + "/shared";
  const std::string map_file = shared + "/room.plx";
  fs::create_directories(shared);
  fs::create_directories(dir + "/a");
  fs::create_directories(dir + "/b");
  DaemonProcess a(kPlenoxdBinary, dir + "/a", SharedFlags(shared));
  DaemonProcess b(kPlenoxdBinary, dir + "/b", SharedFlags(shared));
  const int a_port = a.WaitListening();
  const int b_port = b.WaitListening();
  ASSERT_GT(a_port, 0) << a.Log();
  ASSERT_GT(b_port, 0) << b.Log();
  const int a_metrics = MetricsPort(dir + "/a");
  ASSERT_GT(a_metrics, 0) << a.Log();
  auto a_stub = pb::Plenoxd::NewStub(MakeChannel(a_port));
  auto b_stub = pb::Plenoxd::NewStub(MakeChannel(b_port));

  // A makes the map and saves it under generation 1; B cannot have it meanwhile.
  BuildSmallMap(*a_stub, "room");
  pb::MapInfo a_saved;
  ASSERT_TRUE(SaveMap(*a_stub, "room", &a_saved).ok()) << a.Log();
  const LeaseRecord a_lease = ReadLease(shared, "room");
  EXPECT_EQ(a_lease.token, 1u);
  pb::MapInfo info;
  // B asks A to hand it over (UNAVAILABLE: a client retries), which A, just called, defers.
  grpc::Status refused = GetMap(*b_stub, "room", &info);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::UNAVAILABLE) << Describe(refused);
  EXPECT_NE(refused.error_message().find("owned by another daemon"), std::string::npos)
      << Describe(refused);

  // More keyframes on A, not saved yet; A is paused.
  const IntegrateResult more = Integrate(*a_stub, "room", {5, 15});
  ASSERT_TRUE(more.status.ok()) << Describe(more.status) << a.Log();
  ASSERT_EQ(::kill(a.pid(), SIGSTOP), 0);
  const auto paused_at = std::chrono::steady_clock::now();

  // B takes the map over once A's lease has run out, and saves it under generation 2.
  grpc::Status loaded;
  ASSERT_TRUE(WaitFor(
      [&] {
        loaded = GetMap(*b_stub, "room", &info);
        return loaded.ok();
      },
      absl::Seconds(30)))
      << Describe(loaded) << b.Log();
  const double takeover_s = SecondsSince(paused_at);
  // A's saved copy (or a snapshot of its second batch, if one was due before the pause).
  EXPECT_GE(info.version(), a_saved.version());
  EXPECT_GE(info.keyframes(), a_saved.keyframes());
  pb::MapInfo b_saved;
  ASSERT_TRUE(SaveMap(*b_stub, "room", &b_saved).ok()) << b.Log();
  const LeaseRecord b_lease = ReadLease(shared, "room");
  EXPECT_EQ(b_lease.token, 2u);
  EXPECT_NE(b_lease.holder, a_lease.holder);
  const FileIdentity b_file = Identify(map_file);
  ASSERT_FALSE(b_file.bytes.empty());

  // A resumes: its renewal or its overdue snapshot finds the lease taken over.
  ASSERT_EQ(::kill(a.pid(), SIGCONT), 0);
  ASSERT_TRUE(WaitFor([&] { return MetricValue(a_metrics, "plenoxd_lease_losses_total") >= 1; },
                      absl::Seconds(20)))
      << a.Log();
  // Its clients get the clear error, naming the new owner's generation.
  grpc::Status save = SaveMap(*a_stub, "room");
  EXPECT_EQ(save.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << Describe(save);
  EXPECT_NE(save.error_message().find("generation 2"), std::string::npos) << Describe(save);
  grpc::Status get = GetMap(*a_stub, "room", &info);
  EXPECT_EQ(get.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << Describe(get);
  EXPECT_NE(get.error_message().find("generation 2"), std::string::npos) << Describe(get);
  pb::RenderResponse rendered;
  grpc::Status render = Render(*a_stub, RenderRequestAt("room", 0), &rendered);
  EXPECT_EQ(render.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << Describe(render);
  // Another snapshot interval passes: still nothing from A.
  absl::SleepFor(absl::Seconds(3.5));

  // Writes by the fenced owner: none. The file is the one B renamed into place, byte for byte,
  // the lease still B's, and no staging file of A's is left.
  const FileIdentity after = Identify(map_file);
  const int fenced_writes = after == b_file ? 0 : 1;
  EXPECT_EQ(fenced_writes, 0) << "the map file changed after B's save";
  const absl::StatusOr<MapFileInfo> file = ReadMapInfo(map_file);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->map_version, b_saved.version());
  EXPECT_EQ(ReadLease(shared, "room").token, 2u);
  for (const fs::directory_entry& e : fs::directory_iterator(shared)) {
    EXPECT_EQ(e.path().filename().string().find(".stage."), std::string::npos) << e.path();
  }
  const std::string a_log = a.Log();
  const size_t resumed_log = a_log.find("event=lease_lost");
  const bool snapshot_fenced = a_log.find("event=snapshot_failed map=room") != std::string::npos;
  std::printf("shared storage: lease %.1f s; B took the map over %.2f s after A was paused; "
              "A after SIGCONT: %s; writes by a fenced owner: %d; fenced saves refused: %.0f\n",
              kLeaseSeconds, takeover_s,
              snapshot_fenced ? "its snapshot was refused at the fence"
                              : (resumed_log != std::string::npos ? "its renewal found the loss"
                                                                  : "?"),
              fenced_writes, MetricValue(a_metrics, "plenoxd_fenced_saves_refused_total"));
  EXPECT_LT(takeover_s, kLeaseSeconds + 3.0) << "B waits for the lease, not much longer";

  // B stops (saves, gives its lease up): A may load B's copy again, a generation higher.
  const DaemonProcess::Exit b_exit = b.Stop(std::chrono::seconds(30));
  EXPECT_EQ(b_exit.code, 0) << b.Log();
  ASSERT_TRUE(GetMap(*a_stub, "room", &info).ok()) << a.Log();
  EXPECT_EQ(info.version(), b_saved.version());
  EXPECT_EQ(ReadLease(shared, "room").token, 3u);
  const DaemonProcess::Exit a_exit = a.Stop(std::chrono::seconds(30));
  EXPECT_EQ(a_exit.code, 0) << a.Log();
}

}  // namespace
}  // namespace plx::server::testing

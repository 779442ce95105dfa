// Snapshots and keyframes in map files, end to end (issue 24, parts 1-2): a real plenoxd with
// --snapshot-seconds maps the room over a Slam stream, saves it in the background, and is
// killed with SIGKILL while the stream is still open. The restarted daemon has the map as of
// the snapshot (version, keyframes), and a new Slam stream, started with no pose at all,
// relocalises by the saved keyframes' features and keeps the keyframe count growing from the
// saved one.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "core/formats/map_file.h"
#include "tests/server/daemon_fixture.h"
#include "tests/server/daemon_process.h"

namespace plx::server::testing {
namespace {

namespace fs = std::filesystem;

// The first daemon's stream maps frames 0 .. kFirstRun-1; after the restart a new stream
// comes back a few frames before where it stopped (inside the saved map, where the synthetic
// room's features place a frame within centimetres) and walks on to the end of the room.
constexpr int kFirstRun = 20;
constexpr int kSecondStart = 16;

pb::SlamOptions LockStepSlamOptions() {
  pb::SlamOptions o;
  o.set_voxel_size(kVoxel);
  *o.mutable_tracking() = FastTrackOptions();
  o.set_iterations_per_keyframe(30);
  o.set_rays_per_iteration(2048);
  o.set_deterministic(true);
  return o;
}

std::vector<std::string> DaemonFlags(const std::string& data_dir) {
  return {"--data-dir", data_dir, "--snapshot-seconds", "0.5", "--threads", "2",
          "--metrics-port", "0"};
}

// The value of an unlabelled metric in a Prometheus text answer (-1: absent).
double MetricValue(const std::string& text, const std::string& name) {
  const std::string prefix = "\n" + name + " ";
  const size_t at = text.find(prefix);
  if (at == std::string::npos) return -1;
  double value = -1;
  const size_t start = at + prefix.size();
  const size_t end = text.find('\n', start);
  return absl::SimpleAtod(text.substr(start, end - start), &value) ? value : -1;
}

TEST(SnapshotRestartTest, AfterKillNineTheSnapshotComesBackAndASlamStreamContinuesIt) {
  const std::string dir = plx::testing::MakeTempDir("plx_snapshot_restart");
  const std::string data = dir + "/data";
  fs::create_directories(data);
  fs::create_directories(dir + "/first");
  fs::create_directories(dir + "/second");
  uint64_t saved_version = 0;
  uint32_t saved_keyframes = 0;
  {
    DaemonProcess first(kPlenoxdBinary, dir + "/first", DaemonFlags(data));
    const int port = first.WaitListening();
    ASSERT_GT(port, 0) << first.Log();
    auto stub = pb::Plenoxd::NewStub(MakeChannel(port));
    // One Slam stream, frame by frame (lock-step: each update before the next frame), left
    // open: the daemon dies mid-SLAM.
    grpc::ClientContext context;
    Prepare(&context, "", absl::Seconds(300));
    auto stream = stub->Slam(&context);
    pb::SlamRequest opening;
    opening.set_map("room");
    *opening.mutable_options() = LockStepSlamOptions();
    *opening.mutable_initial_pose() = ToProto(GroundTruth(0));
    ASSERT_TRUE(stream->Write(opening));
    uint32_t accepted = 0;
    for (int i = 0; i < kFirstRun; ++i) {
      pb::SlamRequest request;
      *request.mutable_frame() = EncodeFrame(i, false);
      ASSERT_TRUE(stream->Write(request)) << first.Log();
      pb::SlamUpdate update;
      ASSERT_TRUE(stream->Read(&update)) << first.Log();
      ASSERT_NE(update.state(), pb::SLAM_STATE_LOST) << "frame " << i << ": " << update.reason();
      accepted = update.mapping().keyframes();
    }
    ASSERT_GE(accepted, 2u);
    // Every accepted keyframe integrated, published and snapshot: the map turns clean by
    // itself (no SaveMap, no SIGTERM).
    pb::MapInfo info;
    ASSERT_TRUE(WaitFor(
        [&] {
          return GetMap(*stub, "room", &info).ok() && !info.dirty() &&
                 info.keyframes() == accepted;
        },
        absl::Seconds(60)))
        << info.DebugString() << first.Log();
    saved_version = info.version();
    saved_keyframes = info.keyframes();
    const absl::StatusOr<MapFileInfo> file = ReadMapInfo(data + "/room.plx");
    ASSERT_TRUE(file.ok()) << file.status();
    EXPECT_EQ(file->map_version, saved_version);
    EXPECT_EQ(file->keyframes, static_cast<int64_t>(saved_keyframes));
    // The metrics say so too.
    const int metrics_port = MetricsPort(dir + "/first");
    ASSERT_GT(metrics_port, 0) << first.Log();
    const std::string metrics = HttpGet(metrics_port, "/metrics");
    EXPECT_GE(MetricValue(metrics, "plenoxd_snapshots_total"), 1) << metrics;
    EXPECT_EQ(MetricValue(metrics, "plenoxd_snapshot_failures_total"), 0) << metrics;
    EXPECT_EQ(MetricValue(metrics, "plenoxd_unsaved_maps"), 0) << metrics;
    EXPECT_NE(first.Log().find("event=snapshot_saved map=room"), std::string::npos)
        << first.Log();

    first.Kill();  // no drain, no save: only the snapshot is on disk
    context.TryCancel();
    pb::SlamUpdate ignored;
    while (stream->Read(&ignored)) {
    }
    EXPECT_FALSE(stream->Finish().ok());
  }

  DaemonProcess second(kPlenoxdBinary, dir + "/second", DaemonFlags(data));
  const int port = second.WaitListening();
  ASSERT_GT(port, 0) << second.Log();
  auto stub = pb::Plenoxd::NewStub(MakeChannel(port));
  pb::MapInfo reloaded;
  ASSERT_TRUE(GetMap(*stub, "room", &reloaded).ok()) << second.Log();
  EXPECT_EQ(reloaded.version(), saved_version);
  EXPECT_EQ(reloaded.keyframes(), saved_keyframes);
  EXPECT_FALSE(reloaded.dirty());
  EXPECT_EQ(second.Log().find("map_not_loaded"), std::string::npos) << second.Log();

  // A new stream with no initial pose: only the saved keyframes' features can place it.
  grpc::ClientContext context;
  Prepare(&context, "", absl::Seconds(300));
  auto stream = stub->Slam(&context);
  pb::SlamRequest opening;
  opening.set_map("room");
  *opening.mutable_options() = LockStepSlamOptions();
  ASSERT_TRUE(stream->Write(opening));
  std::vector<pb::SlamUpdate> updates;
  for (int i = kSecondStart; i < kFrames; ++i) {
    pb::SlamRequest request;
    *request.mutable_frame() = EncodeFrame(i, false);
    ASSERT_TRUE(stream->Write(request)) << second.Log();
    pb::SlamUpdate update;
    ASSERT_TRUE(stream->Read(&update)) << second.Log();
    updates.push_back(update);
  }
  stream->WritesDone();
  std::optional<pb::SlamUpdate> done;
  pb::SlamUpdate update;
  while (stream->Read(&update)) {
    if (update.done()) done = update;
  }
  const grpc::Status finished = stream->Finish();
  ASSERT_TRUE(finished.ok()) << Describe(finished) << second.Log();
  ASSERT_TRUE(done.has_value());

  ASSERT_FALSE(updates.empty());
  EXPECT_EQ(updates[0].state(), pb::SLAM_STATE_RELOCALISED) << updates[0].reason();
  EXPECT_NE(updates[0].reason().find("features"), std::string::npos) << updates[0].reason();
  double worst_m = 0.0;
  for (size_t j = 0; j < updates.size(); ++j) {
    const pb::SlamUpdate& u = updates[j];
    const int frame = kSecondStart + static_cast<int>(j);
    EXPECT_NE(u.state(), pb::SLAM_STATE_LOST) << "frame " << frame << ": " << u.reason();
    EXPECT_GE(u.mapping().keyframes(), saved_keyframes) << "frame " << frame;
    EXPECT_GE(u.map_version(), saved_version) << "frame " << frame;
    worst_m = std::max(
        worst_m, (FromProto(u.pose()).translation() - GroundTruth(frame).translation()).norm());
  }
  std::printf("restart: %u keyframes at version %lu saved; the new stream ended with %u, "
              "worst position error %.1f mm\n",
              saved_keyframes, static_cast<unsigned long>(saved_version),
              done->mapping().keyframes(), 1000 * worst_m);
  EXPECT_LT(worst_m, 0.03) << "poses in the saved map's frame";
  EXPECT_GT(done->mapping().keyframes(), saved_keyframes) << "the path went on into new ground";
  pb::MapInfo after;
  ASSERT_TRUE(GetMap(*stub, "room", &after).ok());
  EXPECT_EQ(after.keyframes(), done->mapping().keyframes());
  EXPECT_GT(after.version(), saved_version);

  // SIGTERM saves every accepted keyframe, as before.
  const DaemonProcess::Exit exit = second.Stop(std::chrono::seconds(60));
  EXPECT_EQ(exit.code, 0) << second.Log();
  const absl::StatusOr<MapFileInfo> file = ReadMapInfo(data + "/room.plx");
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->keyframes, static_cast<int64_t>(after.keyframes()));
}

}  // namespace
}  // namespace plx::server::testing

// Limits (concurrent streams, bytes per map, message size) and the Prometheus endpoint.
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

using TrackStream = grpc::ClientReaderWriter<pb::TrackRequest, pb::PoseEstimate>;

// Opens a Track stream on `map` and waits for its first estimate (the daemon has admitted it).
std::unique_ptr<TrackStream> OpenTrack(pb::Plenoxd::Stub& stub, grpc::ClientContext* context,
                                       const std::string& map) {
  Prepare(context);
  auto stream = stub.Track(context);
  pb::TrackRequest r;
  r.set_map(map);
  *r.mutable_options() = FastTrackOptions();
  *r.mutable_initial_pose() = ToProto(GroundTruth(0));
  *r.mutable_frame() = EncodeFrame(0, false);
  EXPECT_TRUE(stream->Write(r));
  pb::PoseEstimate e;
  EXPECT_TRUE(stream->Read(&e));
  return stream;
}

grpc::Status Close(TrackStream& stream) {
  stream.WritesDone();
  pb::PoseEstimate e;
  while (stream.Read(&e)) {
  }
  return stream.Finish();
}

TEST(LimitsTest, ThirdConcurrentStreamIsResourceExhausted) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_streams"));
  o.max_streams = 2;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;

  grpc::ClientContext c1, c2;
  auto s1 = OpenTrack(*d.stub, &c1, "room");
  auto s2 = OpenTrack(*d.stub, &c2, "room");

  // Any third stream: Track, Integrate, Export, WatchJob.
  {
    grpc::ClientContext c;
    Prepare(&c);
    auto s3 = d.stub->Track(&c);
    pb::TrackRequest r;
    r.set_map("room");
    *r.mutable_frame() = EncodeFrame(0, false);
    s3->Write(r);
    const grpc::Status s = Close(*s3);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  }
  {
    const IntegrateResult r = Integrate(*d.stub, "room", {5});
    EXPECT_EQ(r.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(r.status);
    pb::MapInfo info;
    ASSERT_TRUE(GetMap(*d.stub, "room", &info).ok());
    EXPECT_FALSE(info.mapping());
  }
  {
    std::string bytes;
    const grpc::Status s = Export(*d.stub, "room", &bytes);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  }
  // Unary calls are not streams.
  pb::RenderResponse render;
  EXPECT_TRUE(Render(*d.stub, RenderRequestAt("room", 10), &render).ok());

  // Closing one frees its slot (once the daemon has seen the stream end).
  EXPECT_TRUE(Close(*s1).ok());
  EXPECT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 1; }));
  grpc::ClientContext c4;
  auto s4 = OpenTrack(*d.stub, &c4, "room");
  EXPECT_TRUE(Close(*s4).ok());
  EXPECT_TRUE(Close(*s2).ok());
  EXPECT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 0; }));
}

// A map that would outgrow max_map_bytes is never published: the Integrate stream ends
// RESOURCE_EXHAUSTED, the job FAILED, and the map keeps its previous version and content.
TEST(LimitsTest, MapOverTheByteLimitKeepsItsPreviousVersion) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_bytes"));
  o.max_map_bytes = 4096;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::MapInfo before;
  ASSERT_TRUE(CreateMap(*d.stub, "small", kVoxel, &before).ok());

  pb::IntegrateOptions quick;
  quick.set_iterations_per_keyframe(5);
  quick.set_rays_per_iteration(1024);
  const IntegrateResult r = Integrate(*d.stub, "small", {0}, quick);
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(r.status);
  EXPECT_NE(r.status.error_message().find("limit"), std::string::npos) << r.status.error_message();
  for (const pb::MappingProgress& p : r.progress) EXPECT_FALSE(p.done());

  pb::MapInfo after;
  ASSERT_TRUE(GetMap(*d.stub, "small", &after).ok());
  EXPECT_EQ(after.version(), before.version());
  EXPECT_EQ(after.bricks(), 0u);
  EXPECT_EQ(after.keyframes(), 0u);
  EXPECT_FALSE(after.dirty());
  EXPECT_FALSE(after.mapping());

  if (!r.job_id.empty()) {
    grpc::ClientContext c;
    Prepare(&c);
    pb::WatchJobRequest w;
    w.set_job_id(r.job_id);
    auto reader = d.stub->WatchJob(&c, w);
    pb::JobStatus status, last;
    while (reader->Read(&status)) last = status;
    EXPECT_TRUE(reader->Finish().ok());
    EXPECT_EQ(last.state(), pb::JobStatus::STATE_FAILED) << last.message();
  }
  EXPECT_EQ(HealthCheck(*d.health), kServing);
}

// Messages over the daemon's max_message_bytes are refused by gRPC with RESOURCE_EXHAUSTED,
// on a unary call and inside a stream; the daemon carries on.
TEST(LimitsTest, MessageOverTheSizeLimitIsResourceExhausted) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_msg"));
  o.max_message_bytes = 256 << 10;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;

  const grpc::Status unary = CreateMap(*d.stub, std::string(300 << 10, 'n'));
  EXPECT_EQ(unary.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(unary);

  {
    grpc::ClientContext c;
    Prepare(&c);
    auto stream = d.stub->Track(&c);
    pb::TrackRequest r;
    r.set_map("room");
    *r.mutable_initial_pose() = ToProto(GroundTruth(0));
    *r.mutable_frame() = EncodeFrame(0, false);
    ASSERT_TRUE(stream->Write(r));
    pb::PoseEstimate e;
    ASSERT_TRUE(stream->Read(&e));
    pb::TrackRequest big;
    *big.mutable_frame() = EncodeFrame(1, false);
    big.mutable_frame()->set_color(std::string(400 << 10, 'x'));
    stream->Write(big);
    const grpc::Status s = Close(*stream);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  }
  // A response over the limit fails the same way (a 512x384 raw RGB render is 576 KiB).
  {
    pb::RenderRequest request = RenderRequestAt("room", 10);
    request.mutable_intrinsics()->set_width(512);
    request.mutable_intrinsics()->set_height(384);
    request.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
    pb::RenderResponse response;
    const grpc::Status s = Render(*d.stub, request, &response);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
  }

  EXPECT_EQ(HealthCheck(*d.health), kServing);
  const TrackResult tracked = TrackLockStep(*d.stub, "room", {0, 1, 2});
  EXPECT_TRUE(tracked.status.ok()) << Describe(tracked.status);
  EXPECT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 0; }));
}

// --max-frame-pixels: a frame of the room (128x96) is over a limit one pixel smaller, whatever
// its encoding, on Track and Integrate alike: RESOURCE_EXHAUSTED naming the intrinsics and the
// flag, with no image decoded. At exactly the limit it is tracked.
TEST(LimitsTest, FrameOverThePixelLimitIsResourceExhaustedBeforeDecoding) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_pixels"));
  o.max_frame_pixels = kWidth * kHeight - 1;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;

  pb::Frame raw = EncodeFrame(0, false);
  raw.set_color(std::string(kWidth * kHeight * 3, '\x40'));
  raw.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
  raw.set_depth(std::string(kWidth * kHeight * 2, '\x10'));
  raw.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
  const int64_t decoded_before = ImageBuffersDecoded();
  for (const pb::Frame& frame : {EncodeFrame(0, false), raw}) {
    grpc::ClientContext c;
    Prepare(&c);
    auto stream = d.stub->Track(&c);
    pb::TrackRequest r;
    r.set_map("room");
    *r.mutable_frame() = frame;
    stream->Write(r);
    const grpc::Status s = Close(*stream);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);
    EXPECT_NE(s.error_message().find("frame.intrinsics: a 128x96 frame is over the limit of "
                                     "12287 pixels per frame (--max-frame-pixels)"),
              std::string::npos)
        << s.error_message();
  }
  ASSERT_TRUE(CreateMap(*d.stub, "fresh").ok());
  const IntegrateResult integrated = Integrate(*d.stub, "fresh", {0});
  EXPECT_EQ(integrated.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << Describe(integrated.status);
  EXPECT_NE(integrated.status.error_message().find("frame[0].intrinsics"), std::string::npos)
      << integrated.status.error_message();
  EXPECT_EQ(ImageBuffersDecoded(), decoded_before);
  EXPECT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 0; }));

  DaemonOptions at_limit = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_pixels_ok"));
  at_limit.max_frame_pixels = kWidth * kHeight;
  absl::StatusOr<std::unique_ptr<TestDaemon>> ok = StartWithMaps({"room"}, at_limit);
  ASSERT_TRUE(ok.ok()) << ok.status();
  const TrackResult tracked = TrackLockStep(*(*ok)->stub, "room", {0, 1});
  EXPECT_TRUE(tracked.status.ok()) << Describe(tracked.status);
  EXPECT_EQ(tracked.estimates.size(), 2u);
}

// The value of the first sample of `name` (no labels) in a Prometheus text body; -1 if absent.
int64_t Sample(const std::string& body, const std::string& name) {
  for (absl::string_view line : absl::StrSplit(body, '\n')) {
    if (line.empty() || line[0] == '#') continue;
    const std::vector<absl::string_view> fields = absl::StrSplit(line, ' ');
    int64_t value = 0;
    if (fields.size() == 2 && fields[0] == name && absl::SimpleAtoi(fields[1], &value)) {
      return value;
    }
  }
  return -1;
}

TEST(MetricsTest, FramesTrackedAndDroppedMatchTheStreams) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_metrics"));
  o.metrics_port = 0;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  const int port = d.daemon->metrics_port();
  ASSERT_GT(port, 0);

  const std::string idle = HttpGet(port, "/metrics");
  ASSERT_EQ(idle.rfind("HTTP/1.1 200", 0), 0u) << idle.substr(0, 200);
  EXPECT_EQ(Sample(idle, "plenoxd_frames_tracked_total"), 0);
  EXPECT_EQ(Sample(idle, "plenoxd_serving"), 1);
  EXPECT_EQ(Sample(idle, "plenoxd_maps"), 1);

  // 7 frames lock-step, then a burst with drops.
  const TrackResult lock_step = TrackLockStep(*d.stub, "room", {0, 1, 2, 3, 4, 5, 6});
  ASSERT_TRUE(lock_step.status.ok()) << Describe(lock_step.status);
  ASSERT_EQ(lock_step.estimates.size(), 7u);
  int burst_estimates = 0, burst_dropped = 0;
  {
    grpc::ClientContext c;
    Prepare(&c);
    auto stream = d.stub->Track(&c);
    for (int i = 0; i < 12; ++i) {
      pb::TrackRequest r;
      if (i == 0) {
        r.set_map("room");
        *r.mutable_options() = FastTrackOptions(4096);
      }
      *r.mutable_frame() = EncodeFrame(i, false);
      ASSERT_TRUE(stream->Write(r));
    }
    stream->WritesDone();
    pb::PoseEstimate e;
    while (stream->Read(&e)) {
      ++burst_estimates;
      burst_dropped += static_cast<int>(e.dropped());
    }
    ASSERT_TRUE(stream->Finish().ok());
  }
  EXPECT_EQ(burst_estimates + burst_dropped, 12);
  // One bad call.
  pb::MapInfo info;
  EXPECT_FALSE(GetMap(*d.stub, "missing", &info).ok());

  ASSERT_TRUE(WaitFor([&] { return d.daemon->state().metrics->active_streams.load() == 0; }));
  const std::string body = HttpGet(port, "/metrics");
  ASSERT_EQ(body.rfind("HTTP/1.1 200", 0), 0u) << body.substr(0, 200);
  EXPECT_NE(body.find("# TYPE plenoxd_frames_tracked_total counter"), std::string::npos);
  EXPECT_EQ(Sample(body, "plenoxd_frames_tracked_total"), 7 + burst_estimates) << body;
  EXPECT_EQ(Sample(body, "plenoxd_frames_dropped_total"), burst_dropped);
  EXPECT_EQ(Sample(body, "plenoxd_rpc_errors_total"), 1);
  EXPECT_EQ(Sample(body, "plenoxd_active_streams"), 0);
  EXPECT_EQ(Sample(body, "plenoxd_track_latency_seconds_count"), 7 + burst_estimates);

  const std::string other = HttpGet(port, "/other");
  EXPECT_EQ(other.rfind("HTTP/1.1 404", 0), 0u) << other.substr(0, 200);
}

}  // namespace
}  // namespace plx::server::testing

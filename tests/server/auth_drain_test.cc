// Authentication (bearer token on every plenoxd.v1 RPC, health open to all) and the orderly
// drain (health, UNAVAILABLE for new calls, open streams finish or are cancelled at the grace
// deadline, dirty maps saved).
#include <filesystem>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

constexpr char kToken[] = "s3cret-T0ken";

// How a call authenticates: the raw value of its "authorization" header (none when empty).
using CallSetup = std::function<void(grpc::ClientContext*)>;

CallSetup Header(const std::string& value) {
  return [value](grpc::ClientContext* context) {
    Prepare(context, "", absl::Seconds(20));
    if (!value.empty()) context->AddMetadata("authorization", value);
  };
}

template <typename Response, typename Stream>
grpc::Status ReadToEnd(Stream& stream) {
  Response response;
  while (stream->Read(&response)) {
  }
  return stream->Finish();
}

// Every plenoxd.v1 RPC, in an order that succeeds with the right token on a daemon holding the
// map "room": each returns its status. `job_id` carries the Integrate job to WatchJob.
struct Rpc {
  std::string name;
  std::function<grpc::Status(pb::Plenoxd::Stub&, const CallSetup&, std::string* job_id)> call;
};

std::vector<Rpc> AllRpcs() {
  std::vector<Rpc> rpcs;
  rpcs.push_back({"CreateMap", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::CreateMapRequest r;
                    r.set_name("made");
                    r.set_voxel_size(kVoxel);
                    pb::MapInfo info;
                    return stub.CreateMap(&c, r, &info);
                  }});
  rpcs.push_back({"GetMap", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::GetMapRequest r;
                    r.set_name("room");
                    pb::MapInfo info;
                    return stub.GetMap(&c, r, &info);
                  }});
  rpcs.push_back({"ListMaps", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::ListMapsResponse list;
                    return stub.ListMaps(&c, pb::ListMapsRequest(), &list);
                  }});
  rpcs.push_back({"SaveMap", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::SaveMapRequest r;
                    r.set_name("room");
                    pb::MapInfo info;
                    return stub.SaveMap(&c, r, &info);
                  }});
  rpcs.push_back({"LoadMap", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::LoadMapRequest r;
                    r.set_name("room");
                    pb::MapInfo info;
                    return stub.LoadMap(&c, r, &info);
                  }});
  rpcs.push_back({"Render", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::RenderResponse r;
                    return stub.Render(&c, RenderRequestAt("room", 10), &r);
                  }});
  rpcs.push_back({"Export", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::ExportRequest r;
                    r.set_map("room");
                    auto reader = stub.Export(&c, r);
                    return ReadToEnd<pb::ExportChunk>(reader);
                  }});
  rpcs.push_back({"Track", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    auto stream = stub.Track(&c);
                    pb::TrackRequest r;
                    r.set_map("room");
                    *r.mutable_options() = FastTrackOptions();
                    *r.mutable_initial_pose() = ToProto(GroundTruth(0));
                    *r.mutable_frame() = EncodeFrame(0, false);
                    stream->Write(r);
                    pb::TrackRequest next;
                    *next.mutable_frame() = EncodeFrame(1, false);
                    stream->Write(next);
                    stream->WritesDone();
                    return ReadToEnd<pb::PoseEstimate>(stream);
                  }});
  rpcs.push_back({"Integrate", [](pb::Plenoxd::Stub& stub, const CallSetup& setup,
                                  std::string* job) {
                    grpc::ClientContext c;
                    setup(&c);
                    auto stream = stub.Integrate(&c);
                    pb::IntegrateRequest r;
                    r.set_map("made");
                    r.mutable_options()->set_iterations_per_keyframe(5);
                    r.mutable_options()->set_rays_per_iteration(1024);
                    *r.mutable_frame() = EncodeFrame(0, true);
                    stream->Write(r);
                    stream->WritesDone();
                    pb::MappingProgress p;
                    while (stream->Read(&p)) *job = p.job_id();
                    return stream->Finish();
                  }});
  rpcs.push_back({"WatchJob", [](pb::Plenoxd::Stub& stub, const CallSetup& setup,
                                 std::string* job) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::WatchJobRequest r;
                    r.set_job_id(job->empty() ? "integrate-1" : *job);
                    auto reader = stub.WatchJob(&c, r);
                    return ReadToEnd<pb::JobStatus>(reader);
                  }});
  rpcs.push_back({"DeleteMap", [](pb::Plenoxd::Stub& stub, const CallSetup& setup, std::string*) {
                    grpc::ClientContext c;
                    setup(&c);
                    pb::DeleteMapRequest r;
                    r.set_name("made");
                    pb::DeleteMapResponse response;
                    return stub.DeleteMap(&c, r, &response);
                  }});
  return rpcs;
}

TEST(AuthTest, EveryRpcNeedsTheBearerTokenButHealthDoesNot) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_auth"));
  o.auth_token = kToken;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  const std::vector<Rpc> rpcs = AllRpcs();
  ASSERT_EQ(rpcs.size(), 11u) << "plenoxd.v1 has 11 RPCs";

  const std::vector<std::pair<std::string, CallSetup>> rejected = {
      {"no header", Header("")},
      {"wrong token", Header("Bearer wrong")},
      {"token with a suffix", Header(std::string("Bearer ") + kToken + "x")},
      {"token prefix", Header(std::string("Bearer ") + std::string(kToken).substr(0, 5))},
      {"token without Bearer", Header(kToken)},
      {"Basic scheme", Header(std::string("Basic ") + kToken)},
      {"empty bearer", Header("Bearer ")},
  };
  for (const auto& [what, setup] : rejected) {
    for (const Rpc& rpc : rpcs) {
      std::string job;
      const grpc::Status s = rpc.call(*d.stub, setup, &job);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED)
          << rpc.name << " with " << what << ": " << Describe(s);
    }
  }
  // Nothing got through.
  EXPECT_EQ(d.daemon->state().maps->size(), 1);

  // With the token every call works, in order.
  std::string job;
  for (const Rpc& rpc : rpcs) {
    const grpc::Status s = rpc.call(*d.stub, Header(std::string("Bearer ") + kToken), &job);
    EXPECT_TRUE(s.ok()) << rpc.name << ": " << Describe(s);
  }
  EXPECT_FALSE(job.empty());

  // The standard health service answers without a token.
  grpc::Status health_status;
  EXPECT_EQ(HealthCheck(*d.health, &health_status), kServing) << Describe(health_status);
}

TEST(AuthTest, WithoutATokenConfiguredNoHeaderIsNeeded) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  std::string job;
  for (const Rpc& rpc : AllRpcs()) {
    // A header sent anyway is ignored.
    const CallSetup setup = rpc.name == "Render" ? Header("Bearer whatever") : Header("");
    const grpc::Status s = rpc.call(*d.stub, setup, &job);
    EXPECT_TRUE(s.ok()) << rpc.name << ": " << Describe(s);
  }
  EXPECT_EQ(HealthCheck(*d.health), kServing);
}

// One ServerReflectionInfo exchange (list_services) through a generic stub: the call's status,
// and the response's bytes in `response`.
grpc::Status AskReflection(const std::shared_ptr<grpc::Channel>& channel, std::string* response) {
  grpc::GenericStub generic(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext context;
  Prepare(&context, "", absl::Seconds(10));
  auto call = generic.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  auto wait = [&cq](intptr_t expected) {
    void* tag = nullptr;
    bool ok = false;
    EXPECT_TRUE(cq.Next(&tag, &ok));
    EXPECT_EQ(reinterpret_cast<intptr_t>(tag), expected);
    return ok;
  };
  call->StartCall(reinterpret_cast<void*>(1));
  wait(1);
  // ServerReflectionRequest { list_services: "" } is field 7, length 0.
  grpc::Slice slice(std::string("\x3a\x00", 2));
  grpc::ByteBuffer request(&slice, 1);
  call->Write(request, reinterpret_cast<void*>(2));
  wait(2);
  call->WritesDone(reinterpret_cast<void*>(3));
  wait(3);
  grpc::ByteBuffer reply;
  call->Read(&reply, reinterpret_cast<void*>(4));
  if (wait(4)) {
    std::vector<grpc::Slice> slices;
    if (reply.Dump(&slices).ok()) {
      for (const grpc::Slice& s : slices) {
        response->append(reinterpret_cast<const char*>(s.begin()), s.size());
      }
    }
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  wait(5);
  cq.Shutdown();
  void* tag;
  bool ok;
  while (cq.Next(&tag, &ok)) {
  }
  return status;
}

// With authentication on, reflection stays off (daemon.cc: "only the health service answers
// without a token") -- also when another daemon without a token was started in the same
// process before it.
TEST(AuthTest, ReflectionIsOffWithAuthEvenAfterADaemonWithoutAuth) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> open =
      StartTestDaemon(TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_open")));
  ASSERT_TRUE(open.ok()) << open.status();
  std::string listing;
  const grpc::Status open_status = AskReflection((*open)->channel, &listing);
  EXPECT_TRUE(open_status.ok()) << Describe(open_status);
  EXPECT_NE(listing.find("plenoxd.v1.Plenoxd"), std::string::npos) << "reflection lists the API";

  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_closed"));
  o.auth_token = kToken;
  absl::StatusOr<std::unique_ptr<TestDaemon>> closed = StartTestDaemon(o);
  ASSERT_TRUE(closed.ok()) << closed.status();
  std::string leaked;
  const grpc::Status closed_status = AskReflection((*closed)->channel, &leaked);
  EXPECT_EQ(closed_status.error_code(), grpc::StatusCode::UNIMPLEMENTED) << Describe(closed_status);
  EXPECT_EQ(leaked.find("plenoxd.v1.Plenoxd"), std::string::npos)
      << "the daemon with auth_token lists its API to a caller without a token";
}

// Drain with two Track streams open: health stops saying SERVING, new calls are UNAVAILABLE,
// the stream that keeps going finishes OK within the grace period, the idle one is cancelled at
// the deadline, and the map changed by an Integrate is saved as <name>.plx.
TEST(DrainTest, HealthNewCallsOpenStreamsAndSaving) {
  const std::string dir = plx::testing::MakeTempDir("plx_srv_drain");
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"},
                                                                      TestDaemonOptions(dir));
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  EXPECT_EQ(HealthCheck(*d.health), kServing);

  // A dirty map that exists only in memory.
  ASSERT_TRUE(CreateMap(*d.stub, "fresh").ok());
  pb::IntegrateOptions quick;
  quick.set_iterations_per_keyframe(5);
  quick.set_rays_per_iteration(1024);
  const IntegrateResult integrated = Integrate(*d.stub, "fresh", {0}, quick);
  ASSERT_TRUE(integrated.status.ok()) << Describe(integrated.status);
  pb::MapInfo fresh;
  ASSERT_TRUE(GetMap(*d.stub, "fresh", &fresh).ok());
  ASSERT_TRUE(fresh.dirty());
  const std::filesystem::path file = std::filesystem::path(dir) / "fresh.plx";
  ASSERT_FALSE(std::filesystem::exists(file));

  // Two open Track streams, each with its first estimate.
  grpc::ClientContext busy_context, idle_context;
  Prepare(&busy_context);
  Prepare(&idle_context);
  auto busy = d.stub->Track(&busy_context);
  auto idle = d.stub->Track(&idle_context);
  for (auto* stream : {&busy, &idle}) {
    pb::TrackRequest r;
    r.set_map("room");
    *r.mutable_options() = FastTrackOptions();
    *r.mutable_initial_pose() = ToProto(GroundTruth(0));
    *r.mutable_frame() = EncodeFrame(0, false);
    ASSERT_TRUE((*stream)->Write(r));
    pb::PoseEstimate e;
    ASSERT_TRUE((*stream)->Read(&e));
  }

  constexpr absl::Duration kGrace = absl::Seconds(2);
  absl::Status drained;
  absl::Duration drain_took;
  std::thread drainer([&] {
    const absl::Time t0 = absl::Now();
    drained = d.daemon->Drain(kGrace);
    drain_took = absl::Now() - t0;
  });
  struct Joiner {
    std::thread* t;
    ~Joiner() {
      if (t->joinable()) t->join();
    }
  } joiner{&drainer};
  ASSERT_TRUE(WaitFor([&] { return d.daemon->state().draining.load(); }, absl::Seconds(5)));

  // New calls: UNAVAILABLE; health is no longer SERVING (NOT_SERVING, or the call is refused).
  {
    grpc::ClientContext c;
    Prepare(&c, "", absl::Seconds(5));
    pb::ListMapsResponse list;
    const grpc::Status s = d.stub->ListMaps(&c, pb::ListMapsRequest(), &list);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << Describe(s);
  }
  {
    grpc::ClientContext c;
    Prepare(&c, "", absl::Seconds(5));
    auto stream = d.stub->Track(&c);
    pb::TrackRequest r;
    r.set_map("room");
    *r.mutable_frame() = EncodeFrame(0, false);
    stream->Write(r);
    stream->WritesDone();
    const grpc::Status s = ReadToEnd<pb::PoseEstimate>(stream);
    // gRPC's own shutdown may cancel a stream it accepted before the daemon's handler saw it
    // (seen on a loaded machine: CANCELLED without a message); either way it is not served.
    EXPECT_TRUE(s.error_code() == grpc::StatusCode::UNAVAILABLE ||
                (s.error_code() == grpc::StatusCode::CANCELLED && s.error_message() == "CANCELLED"))
        << Describe(s);
  }
  grpc::Status health_status;
  EXPECT_NE(HealthCheck(*d.health, &health_status), kServing);

  // The busy stream keeps tracking within the grace period and ends normally.
  for (int i = 1; i <= 3; ++i) {
    pb::TrackRequest r;
    *r.mutable_frame() = EncodeFrame(i, false);
    r.mutable_frame()->set_timestamp(i / 30.0);
    ASSERT_TRUE(busy->Write(r)) << i;
    pb::PoseEstimate e;
    ASSERT_TRUE(busy->Read(&e)) << i;
    EXPECT_EQ(e.state(), pb::TRACKING_STATE_OK) << e.reason();
  }
  busy->WritesDone();
  const grpc::Status busy_status = ReadToEnd<pb::PoseEstimate>(busy);
  EXPECT_TRUE(busy_status.ok()) << Describe(busy_status);

  // The idle one is cut at the grace deadline.
  const grpc::Status idle_status = ReadToEnd<pb::PoseEstimate>(idle);
  EXPECT_FALSE(idle_status.ok());
  drainer.join();
  EXPECT_TRUE(drained.ok()) << drained;
  EXPECT_GE(drain_took, kGrace - absl::Milliseconds(100));
  EXPECT_LT(drain_took, kGrace + absl::Seconds(5));

  // The dirty map was saved under its name; the clean one was left as it was.
  EXPECT_TRUE(std::filesystem::exists(file));
  EXPECT_TRUE(d.daemon->Drain(kGrace).ok()) << "a second Drain is a no-op";
  absl::StatusOr<std::unique_ptr<TestDaemon>> again = StartTestDaemon(TestDaemonOptions(dir));
  ASSERT_TRUE(again.ok()) << again.status();
  pb::MapInfo loaded;
  ASSERT_TRUE(GetMap(*(*again)->stub, "fresh", &loaded).ok());
  EXPECT_EQ(loaded.bricks(), fresh.bricks());
  EXPECT_FALSE(loaded.dirty());
}

// An open Track stream with its first estimate read.
template <typename Stream>
void StartTracking(Stream& stream) {
  pb::TrackRequest r;
  r.set_map("room");
  *r.mutable_options() = FastTrackOptions();
  *r.mutable_initial_pose() = ToProto(GroundTruth(0));
  *r.mutable_frame() = EncodeFrame(0, false);
  ASSERT_TRUE(stream->Write(r));
  pb::PoseEstimate e;
  ASSERT_TRUE(stream->Read(&e));
}

// The streams a drain cancels at its deadline used to be logged "cancelled by the client",
// sending an operator after clients that did nothing. Only a client's own cancel says that.
TEST(DrainTest, StreamsTheDrainCancelsSaySoAndOnlyAClientCancelBlamesTheClient) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  const auto streams_closed = [&] {
    return d.daemon->state().metrics->active_streams.load() == 0;
  };
  ::testing::internal::CaptureStderr();
  {
    grpc::ClientContext context;
    Prepare(&context);
    auto stream = d.stub->Track(&context);
    StartTracking(stream);
    context.TryCancel();
    EXPECT_EQ(ReadToEnd<pb::PoseEstimate>(stream).error_code(), grpc::StatusCode::CANCELLED);
    // The stream's log line is written before its slot is released.
    EXPECT_TRUE(WaitFor(streams_closed));
  }
  const std::string client_log = ::testing::internal::GetCapturedStderr();

  ::testing::internal::CaptureStderr();
  grpc::ClientContext context;
  Prepare(&context);  // its deadline is far beyond the drain's
  auto idle = d.stub->Track(&context);
  StartTracking(idle);
  const absl::Status drained = d.daemon->Drain(absl::Milliseconds(300));
  const grpc::Status idle_status = ReadToEnd<pb::PoseEstimate>(idle);
  EXPECT_TRUE(WaitFor(streams_closed));
  const std::string drain_log = ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(drained.ok()) << drained;
  // The client gets gRPC's own status for a call the server cancelled (UNAVAILABLE, "Cancelling
  // all calls"); the daemon's side is in its log line.
  EXPECT_FALSE(idle_status.ok());

  EXPECT_NE(client_log.find("method=Track"), std::string::npos) << client_log;
  EXPECT_NE(client_log.find("cancelled by the client"), std::string::npos) << client_log;
  EXPECT_EQ(client_log.find("shutting down"), std::string::npos) << client_log;
  EXPECT_NE(drain_log.find("cancelled: plenoxd is shutting down (the drain's grace period "
                           "ended)"),
            std::string::npos)
      << drain_log;
  EXPECT_EQ(drain_log.find("by the client"), std::string::npos) << drain_log;
}

}  // namespace
}  // namespace plx::server::testing

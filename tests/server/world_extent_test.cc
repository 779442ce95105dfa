// Poses outside the world extent (core/common/world_extent.h) are INVALID_ARGUMENT naming the
// field, on every RPC that takes one. A keyframe 10^10 m away used to be integrated at
// wrapped-around brick coordinates; SaveMap then wrote a file LoadMap refused, and the map was
// lost at the next restart.
#include <string>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

pb::Pose FarPose(double x) {
  pb::Pose p = ToProto(GroundTruth(0));
  p.set_tx(x);
  return p;
}

grpc::Status IntegrateWithPose(TestDaemon& d, const std::string& map, const pb::Pose& pose) {
  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Integrate(&context);
  pb::IntegrateRequest request;
  request.set_map(map);
  *request.mutable_options() = SmallIntegrateOptions();
  *request.mutable_frame() = EncodeFrame(0, true);
  *request.mutable_frame()->mutable_pose() = pose;
  stream->Write(request);
  stream->WritesDone();
  pb::MappingProgress progress;
  while (stream->Read(&progress)) {
  }
  return stream->Finish();
}

TEST(WorldExtentTest, FarKeyframesAreRefusedAndTheMapStillSavesAndLoads) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started =
      StartTestDaemon(TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_world")));
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::MapInfo before;
  ASSERT_TRUE(CreateMap(*d.stub, "m", kVoxel, &before).ok());

  for (double x : {1e10, 1e4 + 1.0, -2e4}) {
    SCOPED_TRACE(x);
    const grpc::Status s = IntegrateWithPose(d, "m", FarPose(x));
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(s);
    EXPECT_NE(s.error_message().find("frame[0].pose"), std::string::npos) << Describe(s);
    EXPECT_NE(s.error_message().find("world extent"), std::string::npos) << Describe(s);
  }
  pb::MapInfo after;
  ASSERT_TRUE(GetMap(*d.stub, "m", &after).ok());
  EXPECT_EQ(after.version(), before.version());
  EXPECT_EQ(after.bricks(), 0u);

  // At the edge of the extent the keyframe is mapped (its depth reaches past it on one side),
  // and what SaveMap writes, LoadMap reads.
  const grpc::Status edge = IntegrateWithPose(d, "m", FarPose(1e4 - 5.0));
  ASSERT_TRUE(edge.ok()) << Describe(edge);
  ASSERT_TRUE(GetMap(*d.stub, "m", &after).ok());
  EXPECT_GT(after.bricks(), 0u);
  const grpc::Status saved = SaveMap(*d.stub, "m");
  ASSERT_TRUE(saved.ok()) << Describe(saved);
  grpc::ClientContext context;
  Prepare(&context);
  pb::LoadMapRequest load;
  load.set_name("m");
  pb::MapInfo loaded;
  const grpc::Status s = d.stub->LoadMap(&context, load, &loaded);
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_EQ(loaded.bricks(), after.bricks());
}

TEST(WorldExtentTest, RenderAndTrackRefuseFarPosesNamingTheField) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::RenderRequest render = RenderRequestAt("room", 10);
  *render.mutable_pose() = FarPose(1e10);
  pb::RenderResponse response;
  const grpc::Status r = Render(*d.stub, render, &response);
  EXPECT_EQ(r.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(r);
  EXPECT_EQ(r.error_message().rfind("pose: translation", 0), 0u) << Describe(r);

  grpc::ClientContext context;
  Prepare(&context);
  auto stream = d.stub->Track(&context);
  pb::TrackRequest request;
  request.set_map("room");
  *request.mutable_initial_pose() = FarPose(-1e10);
  *request.mutable_frame() = EncodeFrame(0, false);
  stream->Write(request);
  stream->WritesDone();
  pb::PoseEstimate estimate;
  while (stream->Read(&estimate)) {
  }
  const grpc::Status t = stream->Finish();
  EXPECT_EQ(t.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(t);
  EXPECT_NE(t.error_message().find("initial_pose"), std::string::npos) << Describe(t);
}

}  // namespace
}  // namespace plx::server::testing

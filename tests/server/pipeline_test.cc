// The whole path of a client: create -> integrate three keyframes -> track every frame in
// lock-step -> render -> export -> save -> drain -> a new daemon on the same data directory
// loads the map at start and renders the same image.
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

// Decodes a RenderResponse's PNG colour and PNG16 depth; fails the test when they do not decode
// or their size is not the request's.
void ExpectDecodes(const pb::RenderResponse& r, cv::Mat* color, cv::Mat* depth) {
  ASSERT_EQ(r.color_encoding(), pb::COLOR_ENCODING_PNG);
  ASSERT_EQ(r.depth_encoding(), pb::DEPTH_ENCODING_PNG16);
  EXPECT_EQ(r.width(), static_cast<uint32_t>(kWidth));
  EXPECT_EQ(r.height(), static_cast<uint32_t>(kHeight));
  absl::StatusOr<cv::Mat> c = DecodeColorBuffer(r.color(), "color");
  ASSERT_TRUE(c.ok()) << c.status();
  absl::StatusOr<cv::Mat> d = DecodeDepthBuffer(r.depth(), "depth");
  ASSERT_TRUE(d.ok()) << d.status();
  EXPECT_EQ(c->cols, kWidth);
  EXPECT_EQ(c->rows, kHeight);
  EXPECT_EQ(d->cols, kWidth);
  EXPECT_EQ(d->rows, kHeight);
  *color = *c;
  *depth = *d;
}

bool SamePixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

TEST(PipelineTest, IntegrateTrackRenderSaveRestartRender) {
  const std::string dir = plx::testing::MakeTempDir("plx_srv_pipeline");
  pb::RenderResponse before;
  {
    absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartTestDaemon(TestDaemonOptions(dir));
    ASSERT_TRUE(started.ok()) << started.status();
    TestDaemon& d = **started;

    // Create and integrate.
    ASSERT_TRUE(CreateMap(*d.stub, "room").ok());
    const IntegrateResult integrated = Integrate(*d.stub, "room", kKeyframes);
    ASSERT_TRUE(integrated.status.ok()) << Describe(integrated.status);
    ASSERT_FALSE(integrated.progress.empty());
    const pb::MappingProgress& last = integrated.progress.back();
    EXPECT_TRUE(last.done());
    EXPECT_EQ(last.keyframes_received(), 3u);
    EXPECT_EQ(last.keyframes_integrated(), 3u);
    EXPECT_EQ(last.iterations(), 3u * SmallIntegrateOptions().iterations_per_keyframe());
    EXPECT_FALSE(last.job_id().empty());
    for (size_t i = 0; i + 1 < integrated.progress.size(); ++i) {
      EXPECT_FALSE(integrated.progress[i].done()) << "done before the last message";
      EXPECT_LE(integrated.progress[i].iterations(), integrated.progress[i + 1].iterations());
      EXPECT_LE(integrated.progress[i].map_version(), integrated.progress[i + 1].map_version());
    }
    pb::MapInfo info;
    ASSERT_TRUE(GetMap(*d.stub, "room", &info).ok());
    EXPECT_EQ(info.version(), last.map_version());
    EXPECT_EQ(info.keyframes(), 3u);
    EXPECT_GT(info.bricks(), 0u);
    EXPECT_GT(info.memory_bytes(), 0u);
    EXPECT_TRUE(info.dirty());
    EXPECT_FALSE(info.mapping());
    // The finished job reads DONE.
    {
      grpc::ClientContext context;
      Prepare(&context);
      pb::WatchJobRequest watch;
      watch.set_job_id(last.job_id());
      auto reader = d.stub->WatchJob(&context, watch);
      pb::JobStatus status, final_status;
      while (reader->Read(&status)) final_status = status;
      ASSERT_TRUE(reader->Finish().ok());
      EXPECT_EQ(final_status.state(), pb::JobStatus::STATE_DONE) << final_status.message();
      EXPECT_EQ(final_status.map(), "room");
      EXPECT_EQ(final_status.kind(), "integrate");
    }

    // Track every frame, lock-step, from the true first pose.
    std::vector<int> frames;
    for (int i = 0; i < kFrames; ++i) frames.push_back(i);
    const TrackResult tracked = TrackLockStep(*d.stub, "room", frames, FastTrackOptions(2048));
    ASSERT_TRUE(tracked.status.ok()) << Describe(tracked.status);
    ASSERT_EQ(tracked.estimates.size(), frames.size());
    for (size_t i = 0; i < frames.size(); ++i) {
      const pb::PoseEstimate& e = tracked.estimates[i];
      EXPECT_EQ(e.state(), pb::TRACKING_STATE_OK) << "frame " << i << ": " << e.reason();
      EXPECT_EQ(e.dropped(), 0u) << "frame " << i;
      EXPECT_DOUBLE_EQ(e.timestamp(), static_cast<double>(i) / 30.0);
      EXPECT_EQ(e.map_version(), info.version());
      if (i > 0) {
        EXPECT_GT(e.valid_rays(), 0u) << "frame " << i;
      }
    }
    // The first estimate echoes the initial pose.
    EXPECT_LT((FromProto(tracked.estimates[0].pose()).translation() - GroundTruth(0).translation())
                  .norm(),
              1e-9);
    const double ate = TranslationRmse(tracked.estimates, frames);
    EXPECT_LT(ate, 0.01) << "ATE " << ate << " m";
    RecordProperty("ate_mm", std::to_string(ate * 1000.0));

    // Render at a keyframe: decodes, the right size, nearly every pixel covered.
    ASSERT_TRUE(Render(*d.stub, RenderRequestAt("room", 10), &before).ok());
    cv::Mat color, depth;
    ExpectDecodes(before, &color, &depth);
    EXPECT_GT(before.coverage(), 0.9);
    EXPECT_EQ(before.map_version(), info.version());
    EXPECT_GT(cv::countNonZero(depth), 0.9 * kWidth * kHeight);

    // Export: a binary PLY in contiguous chunks.
    std::string ply;
    const grpc::Status exported = Export(*d.stub, "room", &ply);
    ASSERT_TRUE(exported.ok()) << Describe(exported);
    EXPECT_EQ(ply.rfind("ply\n", 0), 0u);
    EXPECT_NE(ply.find("binary_little_endian"), std::string::npos);
    EXPECT_GT(ply.size(), 1000u);

    // Save, then stop the daemon.
    pb::MapInfo saved;
    const grpc::Status s = SaveMap(*d.stub, "room", &saved);
    ASSERT_TRUE(s.ok()) << Describe(s);
    EXPECT_FALSE(saved.dirty());
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / "room.plx"));
    const absl::Status drained = d.daemon->Drain(absl::Seconds(2));
    EXPECT_TRUE(drained.ok()) << drained;
  }

  // A new daemon on the same data directory has the map from the start.
  absl::StatusOr<std::unique_ptr<TestDaemon>> restarted = StartTestDaemon(TestDaemonOptions(dir));
  ASSERT_TRUE(restarted.ok()) << restarted.status();
  TestDaemon& d = **restarted;
  grpc::ClientContext context;
  Prepare(&context);
  pb::ListMapsResponse list;
  ASSERT_TRUE(d.stub->ListMaps(&context, pb::ListMapsRequest(), &list).ok());
  ASSERT_EQ(list.maps_size(), 1);
  EXPECT_EQ(list.maps(0).name(), "room");
  EXPECT_FALSE(list.maps(0).dirty());
  EXPECT_GT(list.maps(0).bricks(), 0u);
  EXPECT_FLOAT_EQ(list.maps(0).voxel_size(), kVoxel);

  pb::RenderResponse after;
  ASSERT_TRUE(Render(*d.stub, RenderRequestAt("room", 10), &after).ok());
  cv::Mat color_before, depth_before, color_after, depth_after;
  ExpectDecodes(before, &color_before, &depth_before);
  ExpectDecodes(after, &color_after, &depth_after);
  EXPECT_TRUE(SamePixels(color_before, color_after)) << "colour differs after the restart";
  EXPECT_TRUE(SamePixels(depth_before, depth_after)) << "depth differs after the restart";
  EXPECT_EQ(after.color(), before.color());
  EXPECT_EQ(after.depth(), before.depth());
  EXPECT_DOUBLE_EQ(after.coverage(), before.coverage());
}

}  // namespace
}  // namespace plx::server::testing

// What the viewer shows of a map's SLAM streams stays bounded however long they run: a camera's
// path is halved when full (the whole trajectory stays, at a coarser spacing, and still ends
// where the camera is), the oldest closed camera makes room for a new one, and only the newest
// keyframes are kept.
#include "server/trajectory_record.h"

#include <algorithm>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace plx::server {
namespace {

// A pose whose camera centre is (x, 0, 0): a path's positions then say which frames it kept.
SE3 At(double x) { return SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, 0, 0)); }

std::vector<double> Xs(const web::CameraTrack& track) {
  std::vector<double> xs;
  for (const Eigen::Vector3d& p : track.path) xs.push_back(p.x());
  return xs;
}

// Records frames [from, to) of camera `id`, frame i at At(i).
void RecordFrames(TrajectoryRecord& record, int id, int from, int to) {
  for (int i = from; i < to; ++i) record.Record(id, "", i * 0.1, At(i), SlamState::kOk);
}

TEST(TrajectoryRecordTest, ACameraWaitsThenFollowsItsFrames) {
  TrajectoryRecord record;
  EXPECT_EQ(record.AddCamera(), 0);
  EXPECT_EQ(record.AddCamera(), 1);

  std::vector<web::CameraTrack> cameras = record.Cameras();
  ASSERT_EQ(cameras.size(), 2u);
  EXPECT_EQ(cameras[1].id, 1);
  EXPECT_EQ(cameras[1].label, "camera 1");
  EXPECT_TRUE(cameras[1].active);
  EXPECT_EQ(cameras[1].state, "WAITING");
  EXPECT_EQ(cameras[1].frames, 0);
  EXPECT_TRUE(cameras[1].path.empty());

  // The first frame's label names the camera (cut to 64 characters); later labels do not.
  record.Record(1, std::string(100, 'k'), 1.5, At(1), SlamState::kDegraded);
  record.Record(1, "other", 2.5, At(2), SlamState::kRelocalised);
  record.Record(7, "nobody", 3.0, At(9), SlamState::kOk);  // no such camera: ignored
  record.Close(0);

  cameras = record.Cameras();
  ASSERT_EQ(cameras.size(), 2u);
  EXPECT_FALSE(cameras[0].active);
  EXPECT_EQ(cameras[0].frames, 0);
  EXPECT_EQ(cameras[1].label, std::string(64, 'k'));
  EXPECT_EQ(cameras[1].frames, 2);
  EXPECT_EQ(cameras[1].timestamp, 2.5);
  EXPECT_EQ(cameras[1].state, "RELOCALISED");
  EXPECT_EQ(cameras[1].pose.translation(), At(2).translation());
  EXPECT_EQ(Xs(cameras[1]), (std::vector<double>{1, 2}));
  EXPECT_TRUE(cameras[1].active);
}

TEST(TrajectoryRecordTest, AFullPathKeepsEverySecondPositionThenHalfTheFrames) {
  constexpr int kFull = static_cast<int>(TrajectoryRecord::kMaxPathPoints);
  TrajectoryRecord record;
  const int id = record.AddCamera();
  RecordFrames(record, id, 0, kFull);
  std::vector<double> xs = Xs(record.Cameras()[0]);
  ASSERT_EQ(xs.size(), TrajectoryRecord::kMaxPathPoints);
  EXPECT_EQ(xs.back(), kFull - 1);

  // One more frame: the even frames stay (the first among them), then the new one.
  RecordFrames(record, id, kFull, kFull + 1);
  xs = Xs(record.Cameras()[0]);
  ASSERT_EQ(xs.size(), TrajectoryRecord::kMaxPathPoints / 2 + 1);
  for (size_t i = 0; i < xs.size(); ++i) ASSERT_EQ(xs[i], 2.0 * i) << i;

  // At half the rate an odd frame is not kept, but the path still ends at the camera.
  RecordFrames(record, id, kFull + 1, kFull + 2);
  xs = Xs(record.Cameras()[0]);
  ASSERT_EQ(xs.size(), TrajectoryRecord::kMaxPathPoints / 2 + 2);
  EXPECT_EQ(xs[xs.size() - 2], kFull);
  EXPECT_EQ(xs.back(), kFull + 1);
  RecordFrames(record, id, kFull + 2, kFull + 3);
  xs = Xs(record.Cameras()[0]);
  ASSERT_EQ(xs.size(), TrajectoryRecord::kMaxPathPoints / 2 + 2);
  EXPECT_EQ(xs.back(), kFull + 2);
}

TEST(TrajectoryRecordTest, ALongStreamStaysBoundedFromItsFirstFrameToItsLast) {
  constexpr int kFrames = 10 * static_cast<int>(TrajectoryRecord::kMaxPathPoints) + 3;
  TrajectoryRecord record;
  const int id = record.AddCamera();
  RecordFrames(record, id, 0, kFrames);
  const web::CameraTrack track = record.Cameras()[0];
  EXPECT_EQ(track.frames, kFrames);
  const std::vector<double> xs = Xs(track);
  ASSERT_LE(xs.size(), TrajectoryRecord::kMaxPathPoints + 1);
  ASSERT_GT(xs.size(), TrajectoryRecord::kMaxPathPoints / 2);
  EXPECT_EQ(xs.front(), 0);
  EXPECT_EQ(xs.back(), kFrames - 1);
  // Full at frames 4096, 8192, 16384 and 32768 (of 40963): every 16th frame is kept, and the
  // last point is the camera's own.
  for (size_t i = 1; i + 1 < xs.size(); ++i) ASSERT_EQ(xs[i] - xs[i - 1], 16) << i;
}

TEST(TrajectoryRecordTest, TheOldestClosedCameraMakesRoomThenTheOldest) {
  constexpr int kMax = static_cast<int>(TrajectoryRecord::kMaxCameras);
  TrajectoryRecord record;
  for (int i = 0; i < kMax; ++i) ASSERT_EQ(record.AddCamera(), i);
  record.Close(20);
  record.Close(10);

  // The oldest closed one is camera 10 (joined first), not the last closed.
  EXPECT_EQ(record.AddCamera(), kMax);
  std::vector<int> ids;
  for (const web::CameraTrack& c : record.Cameras()) ids.push_back(c.id);
  ASSERT_EQ(ids.size(), TrajectoryRecord::kMaxCameras);
  EXPECT_EQ(std::count(ids.begin(), ids.end(), 10), 0);
  EXPECT_EQ(std::count(ids.begin(), ids.end(), 20), 1);
  EXPECT_EQ(record.AddCamera(), kMax + 1);  // camera 20 goes
  // Every camera open: the oldest goes, and frames of a dropped camera are ignored.
  EXPECT_EQ(record.AddCamera(), kMax + 2);
  const std::vector<web::CameraTrack> cameras = record.Cameras();
  ASSERT_EQ(cameras.size(), TrajectoryRecord::kMaxCameras);
  EXPECT_EQ(cameras.front().id, 1);
  EXPECT_EQ(cameras.back().id, kMax + 2);
  record.Record(0, "", 1.0, At(1), SlamState::kOk);
  for (const web::CameraTrack& c : record.Cameras()) {
    EXPECT_NE(c.id, 0);
    EXPECT_EQ(c.frames, 0) << c.id;
  }
}

TEST(TrajectoryRecordTest, KeepsTheNewestKeyframesAndReplacesThemEachTime) {
  constexpr size_t kExtra = 10;
  std::vector<StampedPose> keyframes;
  for (size_t i = 0; i < TrajectoryRecord::kMaxKeyframes + kExtra; ++i) {
    keyframes.push_back(StampedPose{static_cast<double>(i), At(static_cast<double>(i))});
  }
  TrajectoryRecord record;
  record.SetKeyframes(keyframes);
  std::vector<SE3> kept = record.Keyframes();
  ASSERT_EQ(kept.size(), TrajectoryRecord::kMaxKeyframes);
  EXPECT_EQ(kept.front().translation().x(), kExtra);
  EXPECT_EQ(kept.back().translation().x(), keyframes.size() - 1);

  record.SetKeyframes({StampedPose{0.0, At(-1)}});
  kept = record.Keyframes();
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0].translation().x(), -1);
}

TEST(TrajectoryRecordTest, LoopsIndexTheKeptKeyframes) {
  constexpr int kExtra = 10;
  std::vector<StampedPose> keyframes;
  for (int i = 0; i < static_cast<int>(TrajectoryRecord::kMaxKeyframes) + kExtra; ++i) {
    keyframes.push_back(StampedPose{static_cast<double>(i), At(static_cast<double>(i))});
  }
  TrajectoryRecord record;
  // A loop to a keyframe no longer kept is dropped; the others shift with the kept ones.
  record.SetKeyframes(keyframes, {{3, 2000}, {kExtra + 5, 3000}});
  const std::vector<std::pair<int, int>> loops = record.Loops();
  ASSERT_EQ(loops.size(), 1u);
  EXPECT_EQ(loops[0], std::make_pair(5, 3000 - kExtra));
  const std::vector<SE3> kept = record.Keyframes();
  EXPECT_EQ(kept[loops[0].first].translation().x(), kExtra + 5);
  record.SetKeyframes(keyframes);
  EXPECT_TRUE(record.Loops().empty());
}

}  // namespace
}  // namespace plx::server

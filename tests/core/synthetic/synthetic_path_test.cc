#include "core/synthetic/synthetic_path.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "core/synthetic/synthetic_scene.h"
#include "core/synthetic/synthetic_sequence.h"
#include "tests/synthetic_distance.h"

namespace plx {
namespace {

constexpr double kFps = 30.0;
constexpr double kRadToDeg = 180.0 / M_PI;
constexpr SyntheticPath kAllPaths[] = {SyntheticPath::kCircle, SyntheticPath::kHeadTurns,
                                       SyntheticPath::kWalkOut, SyntheticPath::kFigureEight,
                                       SyntheticPath::kTwoRoomEight};

// Horizontal viewing direction, radians from world +x towards +y.
double Heading(const SE3& pose) {
  const Eigen::Vector3d f = pose.rotation_matrix().col(2);
  return std::atan2(f.y(), f.x());
}

// Yaw rate (degrees/s) between frames i and i + 1 at 30 fps, by finite differences.
std::vector<double> YawRates(SyntheticPath path, int frames) {
  std::vector<double> rates;
  for (int i = 0; i + 1 < frames; ++i) {
    const double step = std::remainder(Heading(SyntheticPathPose(path, (i + 1) / kFps)) -
                                           Heading(SyntheticPathPose(path, i / kFps)),
                                       2.0 * M_PI);
    rates.push_back(step * kFps * kRadToDeg);
  }
  return rates;
}

TEST(SyntheticPathTest, DefaultPathIsTheCircleAsBefore) {
  const SyntheticOptions options;
  EXPECT_EQ(options.path, SyntheticPath::kCircle);
  for (int i = 0; i < 400; i += 7) {
    const double t = i / kFps;
    EXPECT_EQ(SyntheticCameraPose(options, i).matrix(), SyntheticCameraPoseAtTime(t).matrix());
    EXPECT_EQ(SyntheticPathPose(SyntheticPath::kCircle, t).matrix(),
              SyntheticCameraPoseAtTime(t).matrix());
  }
  // Frames 15 and 37 as `plenox synth` wrote them before the paths were added (groundtruth.txt
  // prints 17 significant digits).
  struct Pinned {
    int frame;
    Eigen::Vector3d t;
    Eigen::Quaterniond q;  // w, x, y, z
  };
  const Pinned pinned[] = {
      {15,
       {0.8831782682275648, -0.3283262277064904, 1.4353553390593272},
       {0.49505125285585805, -0.6916148707318193, -0.4276551438949177, 0.30611142665485636}},
      {37,
       {0.994573159133747, -0.07282769565249164, 1.44667902132486},
       {0.42204482007475996, -0.5915622990679031, -0.559236442341874, 0.3989822273314495}},
  };
  for (const Pinned& p : pinned) {
    const SE3 pose = SyntheticCameraPose(options, p.frame);
    EXPECT_TRUE(pose.translation().isApprox(p.t, 1e-14)) << p.frame;
    EXPECT_TRUE(pose.rotation_matrix().isApprox(p.q.toRotationMatrix(), 1e-14)) << p.frame;
  }
}

TEST(SyntheticPathTest, NamesRoundTripAndUnknownNamesAreRejected) {
  for (SyntheticPath path : kAllPaths) {
    absl::StatusOr<SyntheticPath> parsed = ParseSyntheticPath(SyntheticPathName(path));
    ASSERT_TRUE(parsed.ok()) << parsed.status();
    EXPECT_EQ(*parsed, path);
  }
  EXPECT_STREQ(SyntheticPathName(SyntheticPath::kHeadTurns), "head-turns");
  EXPECT_STREQ(SyntheticPathName(SyntheticPath::kWalkOut), "walk-out");
  EXPECT_STREQ(SyntheticPathName(SyntheticPath::kFigureEight), "figure-eight");
  EXPECT_STREQ(SyntheticPathName(SyntheticPath::kTwoRoomEight), "two-room-eight");
  for (const char* bad : {"", "Circle", "head_turns", "walkout", "circle "}) {
    absl::StatusOr<SyntheticPath> parsed = ParseSyntheticPath(bad);
    EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(parsed.status().message().find("head-turns"), std::string::npos) << bad;
  }
  SyntheticOptions options;
  options.path = static_cast<SyntheticPath>(17);
  EXPECT_EQ(ValidateSyntheticOptions(options).code(), absl::StatusCode::kInvalidArgument);
}

TEST(SyntheticPathTest, HeadTurnsPeakBetween120And150DegreesPerSecondSwingAfterSwing) {
  constexpr int kFrames = 360;  // 12 s
  const std::vector<double> rates = YawRates(SyntheticPath::kHeadTurns, kFrames);
  const double peak = *std::max_element(
      rates.begin(), rates.end(), [](double a, double b) { return std::abs(a) < std::abs(b); });
  EXPECT_GE(std::abs(peak), 120.0);
  EXPECT_LE(std::abs(peak), 150.0);
  // The head looks left and right: the yaw rate changes sign, i.e. the swings beat the
  // circle's own ~30 degrees/s.
  EXPECT_LT(*std::min_element(rates.begin(), rates.end()), -40.0);
  // Sustained: separate bursts above 100 degrees/s, one per swing (2.4 s) after the first.
  int bursts = 0;
  for (size_t i = 0; i < rates.size(); ++i) {
    const bool fast = std::abs(rates[i]) > 100.0;
    if (fast && (i == 0 || std::abs(rates[i - 1]) <= 100.0)) ++bursts;
  }
  EXPECT_GE(bursts, 4);
  // The circle's own yaw rate stays far below the goal's: the swings make this path hard.
  const std::vector<double> circle = YawRates(SyntheticPath::kCircle, kFrames);
  for (double r : circle) EXPECT_LT(std::abs(r), 40.0);
  // The swings only turn the head: the camera travels the circle.
  for (int i = 0; i < kFrames; i += 11) {
    const double t = i / kFps;
    EXPECT_EQ(SyntheticPathPose(SyntheticPath::kHeadTurns, t).translation(),
              SyntheticCameraPoseAtTime(t).translation());
  }
}

TEST(SyntheticPathTest, TheFigureEightCrossesItsCentreTwiceAndRepeatsEvery20Seconds) {
  constexpr SyntheticPath kEight = SyntheticPath::kFigureEight;
  // A loop: the second turn revisits the first's poses exactly.
  for (int i = 0; i < 600; i += 13) {
    const double t = i / kFps;
    EXPECT_TRUE(SyntheticPathPose(kEight, t + 20.0).matrix().isApprox(
        SyntheticPathPose(kEight, t).matrix(), 1e-9))
        << i;
  }
  // The centre at 0 s and 10 s, crossed at headings 60-110 degrees apart: two views of the
  // middle of the room that share only part of what they see.
  const SE3 first = SyntheticPathPose(kEight, 0.0), second = SyntheticPathPose(kEight, 10.0);
  EXPECT_LT(first.translation().head<2>().norm(), 1e-9);
  EXPECT_LT(second.translation().head<2>().norm(), 1e-9);
  const double apart =
      std::abs(std::remainder(Heading(first) - Heading(second), 2.0 * M_PI)) * kRadToDeg;
  EXPECT_GT(apart, 60.0);
  EXPECT_LT(apart, 110.0);
  // It turns both ways (one lobe clockwise, the other counter-clockwise), gently.
  const std::vector<double> rates = YawRates(kEight, 600);
  EXPECT_GT(*std::max_element(rates.begin(), rates.end()), 40.0);
  EXPECT_LT(*std::min_element(rates.begin(), rates.end()), -40.0);
  for (double r : rates) EXPECT_LT(std::abs(r), 70.0);
}

TEST(SyntheticPathTest, TheTwoRoomEightWalksThroughTheDoorwayIntoEachRoomAndRepeats) {
  constexpr SyntheticPath kEight = SyntheticPath::kTwoRoomEight;
  EXPECT_EQ(SyntheticPathScene(kEight), SyntheticSceneKind::kTwoRooms);
  for (SyntheticPath path : kAllPaths) {
    if (path != kEight) {
      EXPECT_EQ(SyntheticPathScene(path), SyntheticSceneKind::kRoom);
    }
  }
  for (int i = 0; i < 900; i += 13) {
    const double t = i / kFps;
    EXPECT_TRUE(SyntheticPathPose(kEight, t + 30.0).matrix().isApprox(
        SyntheticPathPose(kEight, t).matrix(), 1e-9))
        << i;
  }
  // One turn: through the partition (x in [-0.1, 0.1]) only within the doorway, under its
  // lintel, twice; about half the time in each room.
  int crossings = 0, in_plus_x = 0;
  double previous_x = SyntheticPathPose(kEight, 0.0).translation().x();
  for (int i = 1; i <= 900; ++i) {
    const Eigen::Vector3d p = SyntheticPathPose(kEight, i / kFps).translation();
    if (std::abs(p.x()) <= 0.1) {
      EXPECT_LT(std::abs(p.y()), 0.8 - 0.5) << i;
      EXPECT_LT(p.z(), 2.1 - 0.5) << i;
    }
    crossings += (p.x() > 0.0) != (previous_x > 0.0);
    in_plus_x += p.x() > 0.0;
    previous_x = p.x();
  }
  EXPECT_EQ(crossings, 2);
  EXPECT_NEAR(in_plus_x, 450, 2);
  // From the +x room looking back at the partition (heading 180 degrees at 11.25 s), the
  // -x room is seen only through the doorway: every ray that ends beyond the partition
  // crossed x = 0 within it.
  const PinholeIntrinsics k{.fx = 68, .fy = 68, .cx = 40, .cy = 30, .width = 80, .height = 60};
  const SE3 back = SyntheticPathPose(kEight, 11.25);
  ASSERT_GT(back.translation().x(), 2.0);
  const RgbdFrame view = RenderSyntheticView(back, k, 1, SyntheticSceneKind::kTwoRooms);
  int behind_partition = 0, through_doorway = 0;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray((u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy, 1.0);
      const Eigen::Vector3d world = back * (view.depth.pixel(u, v)[0] * ray);
      if (world.x() >= -0.11) continue;
      ++behind_partition;
      const Eigen::Vector3d eye = back.translation();
      const Eigen::Vector3d at_partition = eye + (world - eye) * (eye.x() / (eye.x() - world.x()));
      EXPECT_LT(std::abs(at_partition.y()), 0.8) << u << "," << v;
      EXPECT_LT(at_partition.z(), 2.1) << u << "," << v;
    }
  }
  EXPECT_GT(behind_partition, 0);
  const SE3 before_door = SyntheticPathPose(kEight, 29.0);  // 1 s before the crossing at 30 s
  ASSERT_LT(before_door.translation().x(), -0.5);
  const RgbdFrame door = RenderSyntheticView(before_door, k, 1, SyntheticSceneKind::kTwoRooms);
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray((u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy, 1.0);
      through_doorway += (*door.ground_truth * (door.depth.pixel(u, v)[0] * ray)).x() > 0.11;
    }
  }
  EXPECT_GT(through_doorway, k.width * k.height / 10);
}

TEST(SyntheticPathTest, EveryPathIsSmoothLevelAndKeepsClearOfTheScene) {
  PinholeIntrinsics wide{.fx = 24, .fy = 24, .cx = 20, .cy = 15, .width = 40, .height = 30};
  for (SyntheticPath path : kAllPaths) {
    SCOPED_TRACE(SyntheticPathName(path));
    const SyntheticSceneKind scene = SyntheticPathScene(path);
    const SyntheticScene& room = SyntheticSceneOf(scene);
    for (int i = 0; i < 900; ++i) {  // 30 s: a whole turn of the two-room eight
      const SE3 a = SyntheticPathPose(path, i / kFps), b = SyntheticPathPose(path, (i + 1) / kFps);
      ASSERT_TRUE(a.IsFinite()) << i;
      EXPECT_LT((b.translation() - a.translation()).norm(), 0.03) << i;  // < 0.9 m/s
      EXPECT_LT(RotationAngleBetween(a, b) * kRadToDeg, 5.0) << i;       // < 150 deg/s
      EXPECT_NEAR(a.rotation_matrix().col(0).z(), 0.0, 1e-9) << i;       // no roll
      const Eigen::Vector3d p = a.translation();
      EXPECT_GT(std::min((p - room.room_min).minCoeff(), (room.room_max - p).minCoeff()), 0.5);
      for (const SyntheticBox& box : room.boxes) {
        EXPECT_GT(plx::testing::SignedDistanceToBox(box, p), 0.5) << i;
      }
      if (i % 3 == 0) {
        // Nothing in view closer than 0.5 m (coarse wide-angle render).
        const RgbdFrame frame = RenderSyntheticView(a, wide, 1, scene);
        EXPECT_GT(*std::min_element(frame.depth.data.begin(), frame.depth.data.end()), 0.5f) << i;
      }
    }
  }
}

// Fraction of `frame`'s pixels whose surface point none of `references` sees: it projects
// outside their images, or something nearer covers it there (nearest-pixel depth test).
double UnseenFraction(const RgbdFrame& frame, const std::vector<RgbdFrame>& references,
                      const PinholeIntrinsics& k) {
  int64_t unseen = 0, total = 0;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const float z = frame.depth.pixel(u, v)[0];
      if (z <= 0.0f) continue;
      const Eigen::Vector3d ray((u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy, 1.0);
      const Eigen::Vector3d world = *frame.ground_truth * (z * ray);
      bool seen = false;
      for (const RgbdFrame& ref : references) {
        const Eigen::Vector3d p = ref.ground_truth->Inverse() * world;
        if (p.z() <= 0.1) continue;
        const int ru = static_cast<int>(std::floor(k.fx * p.x() / p.z() + k.cx));
        const int rv = static_cast<int>(std::floor(k.fy * p.y() / p.z() + k.cy));
        if (ru < 0 || rv < 0 || ru >= k.width || rv >= k.height) continue;
        if (std::abs(ref.depth.pixel(ru, rv)[0] - p.z()) < 0.05 * p.z()) {
          seen = true;
          break;
        }
      }
      unseen += !seen;
      ++total;
    }
  }
  return total > 0 ? static_cast<double>(unseen) / total : 0.0;
}

TEST(SyntheticPathTest, WalkOutLooksAtRoomTheFirstFramesNeverSaw) {
  SyntheticOptions options;
  options.width = 80;
  options.height = 60;
  const PinholeIntrinsics k = SyntheticCalibration(options).pinhole;
  auto render = [&](int frame) {
    return RenderSyntheticView(SyntheticPathPose(SyntheticPath::kWalkOut, frame / kFps), k, 1);
  };
  // What the first 1.5 s see (the start of the map).
  std::vector<RgbdFrame> first;
  for (int i : {0, 9, 18, 27, 36, 44}) first.push_back(render(i));

  // The check finds what the first frames did see: frames among and just after them are
  // almost all seen.
  for (int i : {5, 40, 50}) EXPECT_LT(UnseenFraction(render(i), first, k), 0.2) << i;

  // From the second half of the turn on (frame 100, 3.3 s) to 10 s, 200 frames at 30 fps,
  // nearly all of every view is new; a few frames before that, most of it is.
  int mostly_new = 0;
  for (int i = 0; i < 300; ++i) {
    const double unseen = UnseenFraction(render(i), first, k);
    if (i >= 100) {
      EXPECT_GT(unseen, 0.9) << i;
    }
    mostly_new += unseen > 0.5;
  }
  EXPECT_GE(mostly_new, 200);
  EXPECT_LT(mostly_new, 300 - 45);  // the first 1.5 s are not
}

TEST(SyntheticPathTest, GeneratedSequenceFollowsTheChosenPathInItsScene) {
  for (SyntheticPath path : {SyntheticPath::kWalkOut, SyntheticPath::kTwoRoomEight}) {
    SCOPED_TRACE(SyntheticPathName(path));
    SyntheticOptions options;
    options.width = 32;
    options.height = 24;
    options.num_frames = 8;
    options.path = path;
    absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(options);
    ASSERT_TRUE(dataset.ok()) << dataset.status();
    for (int i = 0; i < dataset->size(); ++i) {
      ASSERT_TRUE(dataset->ground_truth(i).has_value());
      EXPECT_EQ(dataset->ground_truth(i)->matrix(), SyntheticPathPose(path, i / kFps).matrix());
      EXPECT_EQ(dataset->frames()[i].depth.data,
                RenderSyntheticView(*dataset->ground_truth(i),
                                    SyntheticCalibration(options).pinhole, 2,
                                    SyntheticPathScene(path))
                    .depth.data);
    }
  }
}

}  // namespace
}  // namespace plx

#include "core/synthetic/synthetic_sequence.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/synthetic/synthetic_scene.h"
#include "tests/synthetic_distance.h"

namespace plx {
namespace {

// Camera-to-world pose at `eye` looking along `forward` with world +z up (OpenCV axes).
// Written independently of the generator's look-at so the tests do not share its mistakes.
SE3 LookAlong(const Eigen::Vector3d& eye, const Eigen::Vector3d& forward) {
  const Eigen::Vector3d f = forward.normalized();
  const Eigen::Vector3d right = f.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d r;
  r << right, f.cross(right), f;
  return SE3(r, eye);
}

PinholeIntrinsics DefaultIntrinsics() { return SyntheticCalibration(SyntheticOptions{}).pinhole; }

// Ray through the centre of pixel (u, v) in camera coordinates, with z = 1.
Eigen::Vector3d PixelRay(const PinholeIntrinsics& k, double u, double v) {
  return {(u + 0.5 - k.cx) / k.fx, (v + 0.5 - k.cy) / k.fy, 1.0};
}

float Depth(const RgbdFrame& frame, int u, int v) { return frame.depth.pixel(u, v)[0]; }

const InMemoryDataset& CleanSequence() {
  static const InMemoryDataset* dataset = [] {
    absl::StatusOr<InMemoryDataset> generated = GenerateSyntheticSequence(SyntheticOptions{});
    EXPECT_TRUE(generated.ok()) << generated.status();
    return new InMemoryDataset(std::move(generated).value());
  }();
  return *dataset;
}

TEST(SyntheticSequenceTest, SizesCalibrationAndGroundTruth) {
  const SyntheticOptions options;
  const InMemoryDataset& dataset = CleanSequence();
  EXPECT_EQ(dataset.name(), "synthetic_room");
  ASSERT_EQ(dataset.size(), 60);

  const CameraCalibration& calibration = dataset.calibration();
  EXPECT_EQ(calibration.pinhole.width, 320);
  EXPECT_EQ(calibration.pinhole.height, 240);
  EXPECT_DOUBLE_EQ(calibration.pinhole.fx, 0.85 * 320);
  EXPECT_DOUBLE_EQ(calibration.pinhole.fy, 0.85 * 320);
  EXPECT_DOUBLE_EQ(calibration.pinhole.cx, 160.0);
  EXPECT_DOUBLE_EQ(calibration.pinhole.cy, 120.0);
  EXPECT_DOUBLE_EQ(calibration.depth_scale, 5000.0);
  EXPECT_TRUE(calibration.distortion.IsZero());
  const double hfov = 2.0 * std::atan(0.5 * 320 / calibration.pinhole.fx) * 180.0 / M_PI;
  EXPECT_GT(hfov, 60.0);
  EXPECT_LT(hfov, 65.0);

  for (int i = 0; i < dataset.size(); ++i) {
    const RgbdFrame& frame = dataset.frames()[i];
    EXPECT_DOUBLE_EQ(dataset.timestamp(i), i / 30.0);
    ASSERT_TRUE(dataset.ground_truth(i).has_value());
    const SE3 expected = SyntheticCameraPose(options, i);
    EXPECT_TRUE(dataset.ground_truth(i)->matrix().isApprox(expected.matrix(), 1e-12));
    ASSERT_EQ(frame.color.width, 320);
    ASSERT_EQ(frame.color.height, 240);
    ASSERT_EQ(frame.color.channels, 3);
    ASSERT_EQ(frame.depth.width, 320);
    ASSERT_EQ(frame.depth.height, 240);
    ASSERT_EQ(frame.depth.channels, 1);
    // Noise-free data: the room is closed, so every pixel sees a surface.
    for (float z : frame.depth.data) ASSERT_TRUE(std::isfinite(z) && z > 0.5f && z < 8.0f) << z;
    for (float c : frame.color.data) ASSERT_TRUE(c >= 0.0f && c <= 1.0f) << c;
  }
}

TEST(SyntheticSequenceTest, DefaultIntrinsicsFollowImageSize) {
  SyntheticOptions options;
  options.width = 64;
  options.height = 48;
  const PinholeIntrinsics k = SyntheticCalibration(options).pinhole;
  EXPECT_DOUBLE_EQ(k.fx, 0.85 * 64);
  EXPECT_DOUBLE_EQ(k.cy, 24.0);
  options.fx = 100;
  options.cx = 30;
  EXPECT_DOUBLE_EQ(SyntheticCalibration(options).pinhole.fx, 100.0);
  EXPECT_DOUBLE_EQ(SyntheticCalibration(options).pinhole.cx, 30.0);
}

TEST(SyntheticSceneTest, DepthFacingWallIsDistanceToWall) {
  const SyntheticScene& room = SyntheticRoom();
  const Eigen::Vector3d eye(0.0, 0.0, 1.5);
  const RgbdFrame frame =
      RenderSyntheticView(LookAlong(eye, Eigen::Vector3d::UnitX()), DefaultIntrinsics());
  // The +x wall is perpendicular to the optical axis, so every pixel on it has the same
  // z-depth; the central region sees only that wall.
  const double expected = room.room_max.x() - eye.x();
  EXPECT_NEAR(Depth(frame, 160, 120), expected, 1e-5);
  for (int v = 60; v < 180; v += 7) {
    for (int u = 100; u < 220; u += 7) ASSERT_NEAR(Depth(frame, u, v), expected, 1e-5);
  }
}

TEST(SyntheticSceneTest, DepthLookingDownIsCameraHeight) {
  const Eigen::Vector3d eye(0.0, 0.0, 1.5);
  Eigen::Matrix3d r;
  r << Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitZ();
  const RgbdFrame frame = RenderSyntheticView(SE3(r, eye), DefaultIntrinsics());
  for (float z : frame.depth.data) ASSERT_NEAR(z, eye.z() - SyntheticRoom().room_min.z(), 1e-5);
}

TEST(SyntheticSceneTest, ObliqueFloorDepthFollowsPixelRays) {
  // Pitched 40 degrees down: the lower image sees the floor at a different depth per row.
  const PinholeIntrinsics k = DefaultIntrinsics();
  const Eigen::Vector3d eye(-0.5, 0.0, 1.4);
  const double pitch = 40.0 * M_PI / 180.0;
  const SE3 pose = LookAlong(eye, Eigen::Vector3d(std::cos(pitch), 0.0, -std::sin(pitch)));
  const RgbdFrame frame = RenderSyntheticView(pose, k);
  int checked = 0;
  for (int v = 130; v < 240; v += 5) {
    for (int u = 0; u < 320; u += 9) {
      const Eigen::Vector3d dir = pose.rotation_matrix() * PixelRay(k, u, v);
      ASSERT_LT(dir.z(), 0.0);
      const double t = eye.z() / -dir.z();  // camera z of the ray is 1, so t is the z-depth
      const Eigen::Vector3d floor_point = eye + t * dir;
      if (std::abs(floor_point.x()) > 1.0 || std::abs(floor_point.y()) > 0.7) continue;
      EXPECT_NEAR(Depth(frame, u, v), t, 1e-5) << u << "," << v;
      ++checked;
    }
  }
  EXPECT_GT(checked, 100);
}

TEST(SyntheticSceneTest, DepthFacingEachBoxIsDistanceToItsFace) {
  const PinholeIntrinsics k = DefaultIntrinsics();
  const SyntheticScene& room = SyntheticRoom();
  ASSERT_GE(room.boxes.size(), 3u);
  ASSERT_LE(room.boxes.size(), 5u);
  constexpr double kDistance = 0.9;
  for (const SyntheticBox& box : room.boxes) {
    // Of the four side faces, take the one whose normal points most towards the room centre
    // and stand kDistance in front of it at the box's mid-height, looking straight at it.
    const double c = std::cos(box.yaw), s = std::sin(box.yaw);
    const Eigen::Vector3d axes[2] = {{c, s, 0.0}, {-s, c, 0.0}};
    const Eigen::Vector3d to_centre = Eigen::Vector3d(-box.center.x(), -box.center.y(), 0.0);
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    double half = 0, best = -2;
    for (int a = 0; a < 2; ++a) {
      for (double sign : {-1.0, 1.0}) {
        const Eigen::Vector3d n = sign * axes[a];
        if (n.dot(to_centre.normalized()) > best) {
          best = n.dot(to_centre.normalized());
          normal = n;
          half = box.half_extents[a];
        }
      }
    }
    const Eigen::Vector3d eye = box.center + (half + kDistance) * normal;
    const RgbdFrame frame = RenderSyntheticView(LookAlong(eye, -normal), k);
    for (int v = 118; v <= 122; ++v) {
      for (int u = 158; u <= 162; ++u) {
        EXPECT_NEAR(Depth(frame, u, v), kDistance, 1e-5) << "box at " << box.center.transpose();
      }
    }
  }
}

TEST(SyntheticSceneTest, TwoRoomsAreJoinedOnlyByTheDoorway) {
  constexpr SyntheticSceneKind kTwo = SyntheticSceneKind::kTwoRooms;
  const SyntheticScene& two = SyntheticSceneOf(kTwo);
  EXPECT_DOUBLE_EQ(two.room_min.x(), -6.0);
  EXPECT_DOUBLE_EQ(two.room_max.x(), 6.0);
  // The -x room is the one room's furniture moved 3 m towards -x.
  const SyntheticScene& one = SyntheticRoom();
  ASSERT_GT(two.boxes.size(), one.boxes.size());
  for (size_t i = 0; i < one.boxes.size(); ++i) {
    EXPECT_EQ(two.boxes[i].center, one.boxes[i].center - Eigen::Vector3d(3.0, 0.0, 0.0));
  }
  const Eigen::Vector3d along_x = Eigen::Vector3d::UnitX();
  // Through the doorway, from the -x room to the far wall of the +x room.
  const SyntheticHit through = CastSyntheticRay({-2.0, 0.0, 1.4}, along_x, kTwo);
  EXPECT_EQ(through.surface, kSyntheticWallMaxX);
  EXPECT_NEAR(through.t, 8.0, 1e-9);
  // Beside the doorway and above it the partition stops the ray at its -x face.
  for (const Eigen::Vector3d& origin : {Eigen::Vector3d(-2.0, 1.2, 1.4),
                                        Eigen::Vector3d(-2.0, -1.2, 1.4),
                                        Eigen::Vector3d(-2.0, 0.0, 2.5)}) {
    const SyntheticHit hit = CastSyntheticRay(origin, along_x, kTwo);
    EXPECT_GE(hit.surface, kSyntheticFirstBox) << origin.transpose();
    EXPECT_NEAR(hit.point.x(), -0.1, 1e-9) << origin.transpose();
    EXPECT_NEAR(hit.normal.x(), -1.0, 1e-9) << origin.transpose();
    EXPECT_GT(SyntheticSurfaceColor(hit, kTwo).sum(), 0.0f);
  }
  // The one room's scene is unchanged by the other's existence: the same ray ends at its wall.
  const SyntheticHit in_one = CastSyntheticRay({-2.0, 0.0, 1.4}, along_x);
  EXPECT_EQ(in_one.surface, kSyntheticWallMaxX);
  EXPECT_NEAR(in_one.t, 5.0, 1e-9);
}

// Back-projects frame a with its depth and ground truth, projects into frame b and compares
// with b's depth, interpolating b's inverse depth bilinearly (exact on planes).
std::vector<double> ReprojectionErrors(const RgbdFrame& a, const RgbdFrame& b,
                                       const PinholeIntrinsics& k) {
  const SE3 b_T_a = b.ground_truth->Inverse() * *a.ground_truth;
  std::vector<double> errors;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const float z = Depth(a, u, v);
      if (z <= 0) continue;
      const Eigen::Vector3d p = b_T_a * (z * PixelRay(k, u, v));
      if (p.z() <= 0.1) continue;
      const double pu = k.fx * p.x() / p.z() + k.cx - 0.5;  // in pixel-index units
      const double pv = k.fy * p.y() / p.z() + k.cy - 0.5;
      const int u0 = static_cast<int>(std::floor(pu)), v0 = static_cast<int>(std::floor(pv));
      if (u0 < 0 || v0 < 0 || u0 + 1 >= k.width || v0 + 1 >= k.height) continue;
      const double zs[4] = {Depth(b, u0, v0), Depth(b, u0 + 1, v0), Depth(b, u0, v0 + 1),
                            Depth(b, u0 + 1, v0 + 1)};
      const auto [lo, hi] = std::minmax_element(zs, zs + 4);
      if (*lo <= 0 || *hi > 1.02 * *lo) continue;  // a depth edge: not one surface
      const double fu = pu - u0, fv = pv - v0;
      const double inverse = (1 - fu) * (1 - fv) / zs[0] + fu * (1 - fv) / zs[1] +
                             (1 - fu) * fv / zs[2] + fu * fv / zs[3];
      errors.push_back(std::abs(1.0 / inverse - p.z()));
    }
  }
  return errors;
}

TEST(SyntheticSequenceTest, MultiViewDepthIsConsistentWithGroundTruth) {
  const InMemoryDataset& dataset = CleanSequence();
  const PinholeIntrinsics& k = dataset.calibration().pinhole;
  for (const auto& [a, b] : std::vector<std::pair<int, int>>{{0, 1}, {0, 15}, {10, 50}}) {
    std::vector<double> errors = ReprojectionErrors(dataset.frames()[a], dataset.frames()[b], k);
    ASSERT_GT(errors.size(), k.width * k.height / 3u) << a << "->" << b;
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    EXPECT_LT(errors[errors.size() / 2], 1e-3) << a << "->" << b;
    std::nth_element(errors.begin(), errors.begin() + errors.size() * 9 / 10, errors.end());
    EXPECT_LT(errors[errors.size() * 9 / 10], 1e-4) << a << "->" << b;
  }
}

TEST(SyntheticSequenceTest, CameraPathIsSmoothAndSweepsTheRoom) {
  const SyntheticOptions options;
  const SyntheticScene& room = SyntheticRoom();
  for (int i = 0; i + 1 < options.num_frames; ++i) {
    const SE3 a = SyntheticCameraPose(options, i), b = SyntheticCameraPose(options, i + 1);
    const double step = (b.translation() - a.translation()).norm();
    EXPECT_GT(step, 0.008) << i;
    EXPECT_LT(step, 0.025) << i;
    const double angle = RotationAngleBetween(a, b) * 180.0 / M_PI;
    EXPECT_GT(angle, 0.5) << i;
    EXPECT_LT(angle, 1.3) << i;
  }
  // Yaw swept by the default sequence: the horizontal viewing direction turns 55-95 degrees.
  auto heading = [](const SE3& pose) {
    const Eigen::Vector3d f = pose.rotation_matrix().col(2);
    return std::atan2(f.y(), f.x());
  };
  double sweep = heading(SyntheticCameraPose(options, options.num_frames - 1)) -
                 heading(SyntheticCameraPose(options, 0));
  sweep = std::remainder(sweep, 2 * M_PI) * 180.0 / M_PI;
  EXPECT_GT(std::abs(sweep), 55.0);
  EXPECT_LT(std::abs(sweep), 95.0);

  // Over a whole turn of the path (12 s) the camera keeps > 0.5 m from every surface, is level
  // (no roll) and the path closes on itself.
  for (double t = 0; t < 12.0; t += 0.05) {
    const SE3 pose = SyntheticCameraPoseAtTime(t);
    const Eigen::Vector3d p = pose.translation();
    const double to_walls =
        std::min((p - room.room_min).minCoeff(), (room.room_max - p).minCoeff());
    EXPECT_GT(to_walls, 0.5) << t;
    for (const SyntheticBox& box : room.boxes) {
      EXPECT_GT(plx::testing::SignedDistanceToBox(box, p), 0.5) << t;
    }
    EXPECT_NEAR(pose.rotation_matrix().col(0).z(), 0.0, 1e-9) << t;  // camera x stays horizontal
  }
  EXPECT_TRUE(SyntheticCameraPoseAtTime(12.0).matrix().isApprox(
      SyntheticCameraPoseAtTime(0.0).matrix(), 1e-9));
}

TEST(SyntheticSequenceTest, NoViewAlongThePathIsPointBlank) {
  // Coarse wide-angle renders around the whole path: nothing in view closer than 0.5 m.
  PinholeIntrinsics k{.fx = 24, .fy = 24, .cx = 20, .cy = 15, .width = 40, .height = 30};
  for (double t = 0; t < 12.0; t += 0.1) {
    const RgbdFrame frame = RenderSyntheticView(SyntheticCameraPoseAtTime(t), k, 1);
    const float nearest = *std::min_element(frame.depth.data.begin(), frame.depth.data.end());
    EXPECT_GT(nearest, 0.5f) << t;
  }
}

TEST(SyntheticSequenceTest, ColourHasGradientsEverywhere) {
  const InMemoryDataset& dataset = CleanSequence();
  for (int i : {0, 30, 59}) {
    const ColorImage& image = dataset.frames()[i].color;
    double sum = 0;
    int64_t count = 0;
    for (int v = 0; v < image.height; ++v) {
      for (int u = 0; u + 1 < image.width; ++u) {
        for (int c = 0; c < 3; ++c) {
          sum += std::abs(image.pixel(u + 1, v)[c] - image.pixel(u, v)[c]);
        }
        count += 3;
      }
    }
    EXPECT_GT(sum / count, 0.012) << i;
    // No flat patches: every 16x16 tile varies in brightness.
    int flat = 0, tiles = 0;
    for (int tv = 0; tv + 16 <= image.height; tv += 16) {
      for (int tu = 0; tu + 16 <= image.width; tu += 16) {
        double mean = 0, square = 0;
        for (int v = tv; v < tv + 16; ++v) {
          for (int u = tu; u < tu + 16; ++u) {
            const float* p = image.pixel(u, v);
            const double y = (p[0] + p[1] + p[2]) / 3.0;
            mean += y;
            square += y * y;
          }
        }
        mean /= 256;
        const double stddev = std::sqrt(std::max(0.0, square / 256 - mean * mean));
        flat += stddev < 0.01;
        ++tiles;
      }
    }
    EXPECT_LE(flat, tiles / 50) << i;
  }
}

TEST(SyntheticSceneTest, ColourIsTheAverageOfTwoByTwoSubsamples) {
  // A 2x2 supersampled pixel averages the rays at offsets 0.25 and 0.75 inside it, i.e. four
  // single-sample renders with the principal point shifted by a quarter pixel.
  const PinholeIntrinsics k = DefaultIntrinsics();
  const SE3 pose = SyntheticCameraPose(SyntheticOptions{}, 20);
  const RgbdFrame supersampled = RenderSyntheticView(pose, k, 2);
  std::vector<double> average(supersampled.color.data.size(), 0.0);
  for (double du : {-0.25, 0.25}) {
    for (double dv : {-0.25, 0.25}) {
      PinholeIntrinsics shifted = k;
      shifted.cx -= du;
      shifted.cy -= dv;
      const RgbdFrame single = RenderSyntheticView(pose, shifted, 1);
      for (size_t i = 0; i < average.size(); ++i) average[i] += 0.25 * single.color.data[i];
    }
  }
  for (size_t i = 0; i < average.size(); ++i) {
    ASSERT_NEAR(supersampled.color.data[i], average[i], 1e-5) << i;
  }
  // Depth still comes from the pixel centre only.
  const RgbdFrame single = RenderSyntheticView(pose, k, 1);
  EXPECT_EQ(single.depth.data, supersampled.depth.data);
}

TEST(SyntheticSequenceTest, RenderedViewMatchesGeneratedFrame) {
  const InMemoryDataset& dataset = CleanSequence();
  const RgbdFrame view =
      RenderSyntheticView(*dataset.ground_truth(17), dataset.calibration().pinhole);
  EXPECT_EQ(view.depth.data, dataset.frames()[17].depth.data);
  EXPECT_EQ(view.color.data, dataset.frames()[17].color.data);
}

TEST(SyntheticSequenceTest, DepthNoiseGrowsWithSquaredDepth) {
  SyntheticOptions options;
  options.num_frames = 4;
  options.depth_noise = 0.004;
  absl::StatusOr<InMemoryDataset> noisy = GenerateSyntheticSequence(options);
  ASSERT_TRUE(noisy.ok()) << noisy.status();
  const InMemoryDataset& clean = CleanSequence();
  // Normalised by z^2 the noise is one Gaussian with sigma = depth_noise; also check that far
  // pixels are noisier than near ones in metres.
  double sum = 0, square = 0, near_square = 0, far_square = 0;
  int64_t count = 0, near_count = 0, far_count = 0;
  for (int i = 0; i < options.num_frames; ++i) {
    const auto& a = clean.frames()[i].depth.data;
    const auto& b = noisy->frames()[i].depth.data;
    for (size_t j = 0; j < a.size(); ++j) {
      ASSERT_GT(b[j], 0.0f);
      const double error = b[j] - a[j];
      const double normalised = error / (double(a[j]) * a[j]);
      sum += normalised;
      square += normalised * normalised;
      ++count;
      if (a[j] < 3.0) {
        near_square += error * error;
        ++near_count;
      } else if (a[j] > 4.0) {
        far_square += error * error;
        ++far_count;
      }
    }
  }
  const double mean = sum / count;
  const double stddev = std::sqrt(square / count - mean * mean);
  EXPECT_NEAR(stddev, options.depth_noise, 0.2 * options.depth_noise);
  EXPECT_LT(std::abs(mean), 0.05 * options.depth_noise);
  ASSERT_GT(near_count, 1000);
  ASSERT_GT(far_count, 1000);
  EXPECT_GT(far_square / far_count, 2.0 * near_square / near_count);
  // Colour is untouched.
  EXPECT_EQ(noisy->frames()[2].color.data, clean.frames()[2].color.data);
}

TEST(SyntheticSequenceTest, HolesHaveTheRequestedFractionAndComeInClusters) {
  SyntheticOptions options;
  options.num_frames = 6;
  options.hole_fraction = 0.1;
  absl::StatusOr<InMemoryDataset> holey = GenerateSyntheticSequence(options);
  ASSERT_TRUE(holey.ok()) << holey.status();
  const InMemoryDataset& clean = CleanSequence();
  for (int i = 0; i < options.num_frames; ++i) {
    const DepthImage& depth = holey->frames()[i].depth;
    const DepthImage& truth = clean.frames()[i].depth;
    auto hole = [&](int u, int v) {
      return u >= 0 && v >= 0 && u < depth.width && v < depth.height && depth.pixel(u, v)[0] == 0;
    };
    int64_t holes = 0, clustered = 0, edges = 0, edge_holes = 0;
    for (int v = 0; v < depth.height; ++v) {
      for (int u = 0; u < depth.width; ++u) {
        const float z = truth.pixel(u, v)[0];
        // Pixels next to a depth jump of more than 10%: the sensor loses these first.
        const bool edge =
            (u + 1 < depth.width && std::abs(truth.pixel(u + 1, v)[0] - z) > 0.1f * z) ||
            (v + 1 < depth.height && std::abs(truth.pixel(u, v + 1)[0] - z) > 0.1f * z);
        edges += edge;
        if (!hole(u, v)) {
          // Kept pixels carry the exact depth (no noise requested).
          ASSERT_EQ(depth.pixel(u, v)[0], z);
          continue;
        }
        ++holes;
        edge_holes += edge;
        const int neighbours = hole(u - 1, v) + hole(u + 1, v) + hole(u, v - 1) + hole(u, v + 1);
        clustered += neighbours >= 2;
      }
    }
    const double fraction = static_cast<double>(holes) / depth.num_pixels();
    EXPECT_NEAR(fraction, options.hole_fraction, 0.01) << i;
    // Independent salt would give ~5% of holes with two hole neighbours; blobs give most.
    EXPECT_GT(static_cast<double>(clustered) / holes, 0.6) << i;
    if (edges > 50) {
      EXPECT_GT(static_cast<double>(edge_holes) / edges, 0.5) << i;
    }
  }
}

TEST(SyntheticSequenceTest, SameSeedGivesIdenticalBytesOtherSeedOtherNoise) {
  SyntheticOptions options;
  options.num_frames = 3;
  options.depth_noise = 0.002;
  options.hole_fraction = 0.05;
  absl::StatusOr<InMemoryDataset> first = GenerateSyntheticSequence(options);
  absl::StatusOr<InMemoryDataset> second = GenerateSyntheticSequence(options);
  options.seed = 8;
  absl::StatusOr<InMemoryDataset> other = GenerateSyntheticSequence(options);
  ASSERT_TRUE(first.ok() && second.ok() && other.ok());
  for (int i = 0; i < options.num_frames; ++i) {
    const RgbdFrame& a = first->frames()[i];
    const RgbdFrame& b = second->frames()[i];
    const RgbdFrame& c = other->frames()[i];
    ASSERT_EQ(a.depth.data.size(), b.depth.data.size());
    EXPECT_EQ(0, std::memcmp(a.depth.data.data(), b.depth.data.data(),
                             a.depth.data.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(a.color.data.data(), b.color.data.data(),
                             a.color.data.size() * sizeof(float)));
    EXPECT_NE(a.depth.data, c.depth.data);
    EXPECT_EQ(a.color.data, c.color.data);
  }
  // Frames do not share a noise stream.
  EXPECT_NE(first->frames()[0].depth.data, first->frames()[1].depth.data);
}

TEST(SyntheticSequenceTest, FewFramesMatchTheSameFramesOfALongerSequence) {
  // Short sequences split rows over threads, long ones split frames: same bytes either way.
  SyntheticOptions options;
  options.width = 160;
  options.height = 120;
  options.num_frames = 1;
  options.depth_noise = 0.003;
  options.hole_fraction = 0.05;
  absl::StatusOr<InMemoryDataset> short_sequence = GenerateSyntheticSequence(options);
  options.num_frames = static_cast<int>(std::max(2u, std::thread::hardware_concurrency()));
  absl::StatusOr<InMemoryDataset> long_sequence = GenerateSyntheticSequence(options);
  ASSERT_TRUE(short_sequence.ok() && long_sequence.ok());
  EXPECT_EQ(short_sequence->frames()[0].depth.data, long_sequence->frames()[0].depth.data);
  EXPECT_EQ(short_sequence->frames()[0].color.data, long_sequence->frames()[0].color.data);
}

TEST(SyntheticSequenceTest, InvalidOptionsAreRejected) {
  auto rejected = [](auto mutate) {
    SyntheticOptions options;
    mutate(options);
    const absl::Status status = GenerateSyntheticSequence(options).status();
    return status.code() == absl::StatusCode::kInvalidArgument;
  };
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.width = 0; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.height = -3; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.num_frames = 0; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.fps = 0; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.fps = NAN; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.fx = -100; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.fy = INFINITY; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.cx = NAN; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.depth_noise = -0.01; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.hole_fraction = 1.0; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.hole_fraction = -0.1; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.hole_fraction = NAN; }));
  EXPECT_TRUE(rejected([](SyntheticOptions& o) { o.depth_scale = 0; }));
  EXPECT_FALSE(rejected([](SyntheticOptions& o) { o.num_frames = 1; }));
}

}  // namespace
}  // namespace plx

#include "core/relocalisation/feature_relocaliser.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// A PnP inlier must also sit at the depth the frame measured there, within this fraction: the
// reprojection test alone cannot tell a point from one further along the same ray.
constexpr float kInlierDepthTolerance = 0.1f;

int Hamming(const OrbDescriptor& a, const OrbDescriptor& b) {
  int bits = 0;
  for (size_t i = 0; i < a.size(); i += 8) {
    uint64_t x, y;
    std::memcpy(&x, a.data() + i, 8);
    std::memcpy(&y, b.data() + i, 8);
    bits += std::popcount(x ^ y);
  }
  return bits;
}

struct Nearest {
  int index = -1;
  int best = std::numeric_limits<int>::max();
  int second = std::numeric_limits<int>::max();
};

// The matching's inner loop: a build for the x86-64 baseline has no popcount instruction, and
// std::popcount there is a library call per word (a check of a frame against 4 keyframes took
// 15-30 ms). A clone for CPUs with the instruction is picked when the program loads.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("popcnt", "default")))
#endif
Nearest NearestOf(const OrbDescriptor& d, const std::vector<OrbDescriptor>& among) {
  Nearest n;
  for (size_t j = 0; j < among.size(); ++j) {
    const int h = Hamming(d, among[j]);
    if (h < n.best) {
      n.second = n.best;
      n.best = h;
      n.index = static_cast<int>(j);
    } else if (h < n.second) {
      n.second = h;
    }
  }
  return n;
}

std::optional<FeatureRelocalisation> PnpAgainst(const FrameFeatures& frame,
                                                const RelocalisationKeyframe& keyframe,
                                                const std::vector<std::pair<int, int>>& matches,
                                                const PinholeIntrinsics& k,
                                                const FeatureRelocaliserOptions& o) {
  std::vector<cv::Point3f> world;
  std::vector<cv::Point2f> pixels;
  world.reserve(matches.size());
  pixels.reserve(matches.size());
  for (const auto& [f, kf] : matches) {
    const Eigen::Vector3d p = keyframe.pose * keyframe.features->points[kf].cast<double>();
    world.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                       static_cast<float>(p.z()));
    // Our pixel convention with our principal point: the projection u = fx x / z + cx is the
    // same model, so neither needs OpenCV's half-pixel shift.
    pixels.emplace_back(frame.pixels[f].x(), frame.pixels[f].y());
  }
  const cv::Matx33d camera(k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0);
  cv::Mat rvec, tvec;
  std::vector<int> ransac_inliers;
  const double inlier_pixels = o.inlier_pixels * k.width / 640.0;
  try {
    // OpenCV's RANSAC seeds its own generator on every call: same inputs, same pose.
    if (!cv::solvePnPRansac(world, pixels, camera, cv::noArray(), rvec, tvec, false,
                            o.ransac_iterations, static_cast<float>(inlier_pixels), 0.999,
                            ransac_inliers, cv::SOLVEPNP_EPNP)) {
      return std::nullopt;
    }
  } catch (const cv::Exception&) {
    return std::nullopt;  // degenerate points (all on a line): no pose from this keyframe
  }
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  Eigen::Matrix3d rotation;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) rotation(i, j) = r(i, j);
  }
  const Eigen::Vector3d translation(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  if (!rotation.allFinite() || !translation.allFinite()) return std::nullopt;
  const SE3 camera_T_world(Eigen::Quaterniond(rotation).normalized(), translation);

  FeatureRelocalisation out;
  out.pose = camera_T_world.Inverse();
  out.keyframe = -1;
  out.matches = static_cast<int>(matches.size());
  for (int i : ransac_inliers) {
    const Eigen::Vector3d in_camera =
        camera_T_world * Eigen::Vector3d(world[i].x, world[i].y, world[i].z);
    const float measured = frame.points[matches[i].first].z();
    if (in_camera.z() > 0.0 &&
        std::abs(in_camera.z() - measured) <= kInlierDepthTolerance * measured) {
      ++out.inliers;
    }
  }
  return out;
}

}  // namespace

absl::Status ValidateFeatureRelocaliserOptions(const FeatureRelocaliserOptions& o) {
  if (o.candidate_keyframes < 1 || o.candidate_keyframes > 64) {
    return absl::InvalidArgumentError(
        absl::StrCat("candidate_keyframes must be in [1, 64], got ", o.candidate_keyframes));
  }
  if (!(o.ratio > 0.0f && o.ratio <= 1.0f)) {
    return absl::InvalidArgumentError(absl::StrCat("ratio must be in (0, 1], got ", o.ratio));
  }
  if (o.max_distance < 1 || o.max_distance > 256) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_distance must be in [1, 256] bits, got ", o.max_distance));
  }
  if (o.min_inliers < 6 || o.min_matches < o.min_inliers) {
    return absl::InvalidArgumentError(absl::StrCat(
        "need 6 <= min_inliers <= min_matches, got ", o.min_inliers, " and ", o.min_matches));
  }
  if (!(o.inlier_pixels > 0.0) || !std::isfinite(o.inlier_pixels)) {
    return absl::InvalidArgumentError(
        absl::StrCat("inlier_pixels must be positive, got ", o.inlier_pixels));
  }
  if (o.ransac_iterations < 10 || o.ransac_iterations > 10000) {
    return absl::InvalidArgumentError(
        absl::StrCat("ransac_iterations must be in [10, 10000], got ", o.ransac_iterations));
  }
  return absl::OkStatus();
}

std::vector<int> RankKeyframes(const FrameFeatures& frame,
                               const std::vector<RelocalisationKeyframe>& keyframes, int count,
                               float min_similarity) {
  std::vector<std::pair<float, int>> scored;
  for (size_t i = 0; i < keyframes.size(); ++i) {
    if (keyframes[i].features == nullptr) continue;
    const float s = ThumbnailSimilarity(frame, *keyframes[i].features);
    if (s >= min_similarity) scored.emplace_back(s, static_cast<int>(i));
  }
  // Most similar first; ties by index, so the order never depends on the sort's internals.
  std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  std::vector<int> out;
  for (int i = 0; i < std::min<int>(count, static_cast<int>(scored.size())); ++i) {
    out.push_back(scored[i].second);
  }
  return out;
}

std::vector<std::pair<int, int>> MatchFeatures(const FrameFeatures& frame,
                                               const FrameFeatures& keyframe,
                                               const FeatureRelocaliserOptions& o) {
  std::vector<std::pair<int, int>> matches;
  if (frame.descriptors.empty() || keyframe.descriptors.empty()) return matches;
  for (size_t i = 0; i < frame.descriptors.size(); ++i) {
    const Nearest n = NearestOf(frame.descriptors[i], keyframe.descriptors);
    if (n.index < 0 || n.best > o.max_distance) continue;
    if (n.second != std::numeric_limits<int>::max() &&
        static_cast<float>(n.best) >= o.ratio * static_cast<float>(n.second)) {
      continue;  // ambiguous: a repeated texture
    }
    // Mutual: the keyframe's descriptor has this one as its nearest too.
    if (NearestOf(keyframe.descriptors[n.index], frame.descriptors).index !=
        static_cast<int>(i)) {
      continue;
    }
    matches.emplace_back(static_cast<int>(i), n.index);
  }
  return matches;
}

std::optional<FeatureRelocalisation> RelocaliseByFeatures(
    const FrameFeatures& frame, const std::vector<RelocalisationKeyframe>& keyframes,
    const PinholeIntrinsics& k, const FeatureRelocaliserOptions& o) {
  if (frame.size() < o.min_inliers) return std::nullopt;
  std::optional<FeatureRelocalisation> best;
  for (int index : RankKeyframes(frame, keyframes, o.candidate_keyframes)) {
    const RelocalisationKeyframe& keyframe = keyframes[index];
    const std::vector<std::pair<int, int>> matches =
        MatchFeatures(frame, *keyframe.features, o);
    if (static_cast<int>(matches.size()) < o.min_matches) continue;
    std::optional<FeatureRelocalisation> found = PnpAgainst(frame, keyframe, matches, k, o);
    if (!found || found->inliers < o.min_inliers) continue;
    found->keyframe = index;
    if (!best || found->inliers > best->inliers) best = found;
  }
  return best;
}

}  // namespace plx

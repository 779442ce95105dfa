#include "core/relocalisation/frame_features.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "core/geometry/luma.h"

namespace plx {
namespace {

// A keypoint's depth must agree with its 3x3 neighbourhood within this fraction: on an
// object's silhouette the pixel may be foreground while the patch the descriptor saw is mostly
// background (or the other way round), and its 3D point would be wrong by the gap.
constexpr float kDepthSpreadTolerance = 0.05f;

cv::Mat GreyOf(const ColorImage& color) {
  cv::Mat grey(color.height, color.width, CV_8UC1);
  const float* rgb = color.data.data();
  for (int v = 0; v < color.height; ++v) {
    auto* row = grey.ptr<uint8_t>(v);
    for (int u = 0; u < color.width; ++u, rgb += 3) {
      row[u] = static_cast<uint8_t>(std::clamp(Luma(rgb) * 255.0f + 0.5f, 0.0f, 255.0f));
    }
  }
  return grey;
}

bool InRange(float d, const FrameFeatureOptions& o) { return d > o.min_depth && d <= o.max_depth; }

// The depth under a keypoint when its neighbourhood is one surface, else 0.
float KeypointDepth(const DepthImage& depth, int u, int v, const FrameFeatureOptions& o) {
  const float d = depth.data[static_cast<size_t>(v) * depth.width + u];
  if (!InRange(d, o)) return 0.0f;
  for (int dv = -1; dv <= 1; ++dv) {
    for (int du = -1; du <= 1; ++du) {
      const int x = u + du, y = v + dv;
      if (x < 0 || y < 0 || x >= depth.width || y >= depth.height) continue;
      const float n = depth.data[static_cast<size_t>(y) * depth.width + x];
      if (InRange(n, o) && std::abs(n - d) > kDepthSpreadTolerance * d) return 0.0f;
    }
  }
  return d;
}

void FillThumbnail(const cv::Mat& grey, int width, FrameFeatures* out) {
  const int height = std::max(1, static_cast<int>(std::lround(
                                     static_cast<double>(width) * grey.rows / grey.cols)));
  cv::Mat small;
  cv::resize(grey, small, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  out->thumbnail_width = width;
  out->thumbnail_height = height;
  out->thumbnail.resize(static_cast<size_t>(width) * height);
  double sum = 0.0;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const float value = small.at<uint8_t>(v, u) / 255.0f;
      out->thumbnail[static_cast<size_t>(v) * width + u] = value;
      sum += value;
    }
  }
  const auto mean = static_cast<float>(sum / static_cast<double>(out->thumbnail.size()));
  double norm2 = 0.0;
  for (float& value : out->thumbnail) {
    value -= mean;
    norm2 += static_cast<double>(value) * value;
  }
  // A flat image (a covered lens) has no pattern to compare: it stays all zero and is
  // similar to nothing.
  const double norm = std::sqrt(norm2);
  const float scale = norm > 1e-6 ? static_cast<float>(1.0 / norm) : 0.0f;
  for (float& value : out->thumbnail) value *= scale;
}

}  // namespace

absl::Status ValidateFrameFeatureOptions(const FrameFeatureOptions& o) {
  if (o.max_features < 8 || o.max_features > 10000) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_features must be in [8, 10000], got ", o.max_features));
  }
  if (!(o.min_depth >= 0.0f) || !(o.max_depth > o.min_depth) || !std::isfinite(o.max_depth)) {
    return absl::InvalidArgumentError(absl::StrCat("feature depth range (", o.min_depth, ", ",
                                                   o.max_depth, "] is not a range"));
  }
  if (o.thumbnail_width < 4 || o.thumbnail_width > 256) {
    return absl::InvalidArgumentError(
        absl::StrCat("thumbnail_width must be in [4, 256], got ", o.thumbnail_width));
  }
  return absl::OkStatus();
}

absl::StatusOr<FrameFeatures> ExtractFrameFeatures(const RgbdFrame& frame,
                                                   const PinholeIntrinsics& k,
                                                   const FrameFeatureOptions& options) {
  if (frame.color.width != k.width || frame.color.height != k.height ||
      frame.depth.width != k.width || frame.depth.height != k.height ||
      frame.color.channels != 3 || frame.depth.channels != 1 || k.width <= 0 || k.height <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "features: colour ", frame.color.width, "x", frame.color.height, " and depth ",
        frame.depth.width, "x", frame.depth.height, " do not match the intrinsics ", k.width,
        "x", k.height));
  }
  FrameFeatures out;
  const cv::Mat grey = GreyOf(frame.color);
  FillThumbnail(grey, std::min(options.thumbnail_width, k.width), &out);

  // Only where there is depth: a keypoint without it cannot give a 3D point.
  cv::Mat mask(k.height, k.width, CV_8UC1);
  for (int v = 0; v < k.height; ++v) {
    auto* row = mask.ptr<uint8_t>(v);
    for (int u = 0; u < k.width; ++u) {
      row[u] = InRange(frame.depth.data[static_cast<size_t>(v) * k.width + u], options) ? 255 : 0;
    }
  }
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  try {
    cv::Ptr<cv::ORB> orb = cv::ORB::create(options.max_features);
    orb->detectAndCompute(grey, mask, keypoints, descriptors);
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("ORB features: ", e.what()));
  }
  for (size_t i = 0; i < keypoints.size(); ++i) {
    // OpenCV puts a pixel's centre at its integer coordinate; ours is at +0.5.
    const int u = std::clamp(static_cast<int>(std::lround(keypoints[i].pt.x)), 0, k.width - 1);
    const int v = std::clamp(static_cast<int>(std::lround(keypoints[i].pt.y)), 0, k.height - 1);
    const float z = KeypointDepth(frame.depth, u, v, options);
    if (z == 0.0f) continue;
    const Eigen::Vector2f pixel(keypoints[i].pt.x + 0.5f, keypoints[i].pt.y + 0.5f);
    out.pixels.push_back(pixel);
    out.points.emplace_back(static_cast<float>((pixel.x() - k.cx) / k.fx) * z,
                            static_cast<float>((pixel.y() - k.cy) / k.fy) * z, z);
    OrbDescriptor d;
    std::memcpy(d.data(), descriptors.ptr<uint8_t>(static_cast<int>(i)), d.size());
    out.descriptors.push_back(d);
  }
  return out;
}

float ThumbnailSimilarity(const FrameFeatures& a, const FrameFeatures& b) {
  if (a.thumbnail.size() != b.thumbnail.size() || a.thumbnail_width != b.thumbnail_width ||
      a.thumbnail.empty()) {
    return -1.0f;
  }
  double dot = 0.0;
  for (size_t i = 0; i < a.thumbnail.size(); ++i) {
    dot += static_cast<double>(a.thumbnail[i]) * b.thumbnail[i];
  }
  return static_cast<float>(dot);
}

}  // namespace plx

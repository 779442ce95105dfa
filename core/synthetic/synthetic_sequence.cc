#include "core/synthetic/synthetic_sequence.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/synthetic/synthetic_scene.h"

namespace plx {
namespace {

// ---------------------------------------------------------------------------------------------
// Sensor corruption.

uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// Marks about hole_fraction of the pixels: up to 30% of the budget on depth discontinuities
// (where real sensors lose the return), the rest as small ellipses of 1.5-4.5 px radius at
// 320x240 (scaled with the image), like the blobs a structured-light sensor misses.
std::vector<uint8_t> MakeHoleMask(const DepthImage& depth, double hole_fraction,
                                  std::mt19937_64& rng) {
  const int w = depth.width, h = depth.height;
  const int64_t n = depth.num_pixels();
  std::vector<uint8_t> hole(n, 0);
  const int64_t target = std::llround(hole_fraction * static_cast<double>(n));
  if (target == 0) return hole;
  auto z = [&](int u, int v) { return depth.data[static_cast<int64_t>(v) * w + u]; };

  std::vector<int64_t> edges;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const float z0 = z(u, v);
      const float threshold = 0.04f * z0;  // planes in view change less per pixel at 320x240
      const bool jump = (u + 1 < w && std::abs(z(u + 1, v) - z0) > threshold) ||
                        (u > 0 && std::abs(z(u - 1, v) - z0) > threshold) ||
                        (v + 1 < h && std::abs(z(u, v + 1) - z0) > threshold) ||
                        (v > 0 && std::abs(z(u, v - 1) - z0) > threshold);
      if (jump) edges.push_back(static_cast<int64_t>(v) * w + u);
    }
  }
  int64_t count = 0;
  if (!edges.empty()) {
    const double keep = std::min(1.0, 0.3 * static_cast<double>(target) / edges.size());
    std::bernoulli_distribution take(keep);
    for (int64_t index : edges) {
      if (take(rng)) {
        hole[index] = 1;
        ++count;
      }
    }
  }

  const double scale = std::sqrt(static_cast<double>(n) / (320.0 * 240.0));
  std::uniform_real_distribution<double> pick_u(0.0, w), pick_v(0.0, h);
  std::uniform_real_distribution<double> pick_radius(1.5 * scale, 4.5 * scale);
  // A blob lands on at least one free pixel far more often than not; the cap only guards
  // against pathological sizes.
  for (int64_t attempt = 0; count < target && attempt < 100 * n; ++attempt) {
    const double bu = pick_u(rng), bv = pick_v(rng);
    const double ru = pick_radius(rng), rv = pick_radius(rng);
    const int u0 = std::max(0, static_cast<int>(std::floor(bu - ru)));
    const int u1 = std::min(w - 1, static_cast<int>(std::ceil(bu + ru)));
    const int v0 = std::max(0, static_cast<int>(std::floor(bv - rv)));
    const int v1 = std::min(h - 1, static_cast<int>(std::ceil(bv + rv)));
    for (int v = v0; v <= v1 && count < target; ++v) {
      for (int u = u0; u <= u1 && count < target; ++u) {
        const double du = (u + 0.5 - bu) / ru, dv = (v + 0.5 - bv) / rv;
        const int64_t index = static_cast<int64_t>(v) * w + u;
        if (du * du + dv * dv <= 1.0 && !hole[index]) {
          hole[index] = 1;
          ++count;
        }
      }
    }
  }
  return hole;
}

void CorruptDepth(const SyntheticOptions& options, int frame_index, DepthImage* depth) {
  if (options.depth_noise <= 0.0 && options.hole_fraction <= 0.0) return;
  // One generator per frame, seeded from (seed, index): frames can be made in any order.
  std::mt19937_64 rng(SplitMix64(options.seed ^ SplitMix64(static_cast<uint64_t>(frame_index))));
  const std::vector<uint8_t> hole = MakeHoleMask(*depth, options.hole_fraction, rng);
  std::normal_distribution<double> gaussian(0.0, 1.0);
  for (int64_t i = 0; i < depth->num_pixels(); ++i) {
    float& z = depth->data[i];
    if (hole[i] || z <= 0.0f) {
      z = 0.0f;
      continue;
    }
    if (options.depth_noise > 0.0) {
      const double noisy = z + options.depth_noise * z * z * gaussian(rng);
      z = noisy > 0.0 ? static_cast<float>(noisy) : 0.0f;  // a sensor reports no negative depth
    }
  }
}

}  // namespace

absl::Status ValidateSyntheticOptions(const SyntheticOptions& options) {
  if (options.width <= 0 || options.height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("image size must be positive, got ", options.width, "x", options.height));
  }
  if (options.num_frames < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("num_frames must be >= 1, got ", options.num_frames));
  }
  if (!(std::isfinite(options.fps) && options.fps > 0)) {
    return absl::InvalidArgumentError(absl::StrCat("fps must be positive, got ", options.fps));
  }
  if (!(std::isfinite(options.depth_noise) && options.depth_noise >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("depth_noise must be >= 0, got ", options.depth_noise));
  }
  if (!(options.hole_fraction >= 0 && options.hole_fraction < 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("hole_fraction must be in [0, 1), got ", options.hole_fraction));
  }
  if (options.path != SyntheticPath::kCircle && options.path != SyntheticPath::kHeadTurns &&
      options.path != SyntheticPath::kWalkOut && options.path != SyntheticPath::kFigureEight &&
      options.path != SyntheticPath::kTwoRoomEight) {
    return absl::InvalidArgumentError(
        absl::StrCat("unknown synthetic path ", static_cast<int>(options.path)));
  }
  for (double value : {options.fx, options.fy, options.cx, options.cy}) {
    if (!(std::isfinite(value) && value >= 0)) {
      return absl::InvalidArgumentError(
          "fx, fy, cx, cy must be finite and >= 0 (0 derives them from the image size)");
    }
  }
  return ValidateCalibration(SyntheticCalibration(options));
}

CameraCalibration SyntheticCalibration(const SyntheticOptions& options) {
  CameraCalibration calibration;
  PinholeIntrinsics& k = calibration.pinhole;
  k.width = options.width;
  k.height = options.height;
  k.fx = options.fx != 0 ? options.fx : 0.85 * options.width;
  k.fy = options.fy != 0 ? options.fy : 0.85 * options.width;
  k.cx = options.cx != 0 ? options.cx : 0.5 * options.width;
  k.cy = options.cy != 0 ? options.cy : 0.5 * options.height;
  calibration.depth_scale = options.depth_scale;
  return calibration;
}

SE3 SyntheticCameraPose(const SyntheticOptions& options, int frame_index) {
  return SyntheticPathPose(options.path, frame_index / options.fps);
}

absl::StatusOr<InMemoryDataset> GenerateSyntheticSequence(const SyntheticOptions& options) {
  PLX_RETURN_IF_ERROR(ValidateSyntheticOptions(options));
  const CameraCalibration calibration = SyntheticCalibration(options);
  const PinholeIntrinsics& k = calibration.pinhole;
  std::vector<RgbdFrame> frames(options.num_frames);

  auto make_frame = [&](int i, bool split_rows) {
    RgbdFrame& frame = frames[i];
    const SE3 pose = SyntheticCameraPose(options, i);
    const SyntheticSceneKind scene = SyntheticPathScene(options.path);
    if (split_rows) {
      frame = RenderSyntheticView(pose, k, /*supersampling=*/2, scene);
    } else {
      frame.ground_truth = pose;
      frame.color = ColorImage(k.width, k.height, 3);
      frame.depth = DepthImage(k.width, k.height, 1);
      internal::RenderSyntheticRows(pose, k, /*supersampling=*/2, scene, 0, k.height, &frame);
    }
    frame.timestamp = i / options.fps;
    CorruptDepth(options, i, &frame.depth);
  };

  // Rows and frames are independent and noise is seeded per frame, so the split does not
  // change the output: short sequences split each frame's rows over threads, longer ones give
  // each thread whole frames (less synchronisation).
  const int hardware = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (options.num_frames < hardware) {
    for (int i = 0; i < options.num_frames; ++i) make_frame(i, /*split_rows=*/true);
  } else {
    std::atomic<int> next{0};
    auto worker = [&] {
      for (int i = next++; i < options.num_frames; i = next++) make_frame(i, false);
    };
    std::vector<std::thread> threads;
    for (int t = 1; t < hardware; ++t) threads.emplace_back(worker);
    worker();
    for (std::thread& t : threads) t.join();
  }

  return InMemoryDataset(kSyntheticSequenceName, calibration, std::move(frames));
}

}  // namespace plx

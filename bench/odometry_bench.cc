// plx_odometry_bench: what the map-free odometry (core/odometry/rgbd_odometry.h) costs and how
// well it does per frame on the synthetic room: each frame against the one before it, from the
// identity (no motion model), at the 640x480 or any size.
//
//   build/bench/plx_odometry_bench [--width 640 --height 480 --frames 60 --step 1]
//
// --step K aligns frame i to frame i + K (K times the motion per frame). Prints per-frame
// pyramid and alignment milliseconds (median, max) and the translation / rotation error against
// the ground truth (median, max).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/odometry/rgbd_odometry.h"
#include "core/synthetic/synthetic_sequence.h"

namespace {

double Millis(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

double Max(const std::vector<double>& v) {
  return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
}

}  // namespace

int main(int argc, char** argv) {
  plx::SyntheticOptions s;
  s.width = 640;
  s.height = 480;
  s.num_frames = 60;
  int step = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    const int value = std::atoi(argv[i + 1]);
    if (flag == "--width") s.width = value;
    else if (flag == "--height") s.height = value;
    else if (flag == "--frames") s.num_frames = value;
    else if (flag == "--step") step = value;
    else {
      std::fprintf(stderr, "unknown flag %s\n", argv[i]);
      return 2;
    }
  }
  if (step < 1 || s.num_frames <= step) {
    std::fprintf(stderr, "need --step >= 1 and --frames > --step\n");
    return 2;
  }
  absl::StatusOr<plx::InMemoryDataset> seq = plx::GenerateSyntheticSequence(s);
  if (!seq.ok()) {
    std::fprintf(stderr, "%s\n", std::string(seq.status().message()).c_str());
    return 1;
  }
  const plx::PinholeIntrinsics k = seq->calibration().pinhole;
  std::vector<double> pyramid_ms, align_ms, error_cm, error_deg;
  int not_ok = 0;
  std::vector<plx::OdometryPyramid> pyramids;
  for (const plx::RgbdFrame& f : seq->frames()) {
    const auto t0 = std::chrono::steady_clock::now();
    absl::StatusOr<plx::OdometryPyramid> p =
        plx::BuildOdometryPyramid(f, k, plx::OdometryPyramidOptions());
    pyramid_ms.push_back(Millis(t0, std::chrono::steady_clock::now()));
    if (!p.ok()) return 1;
    pyramids.push_back(*std::move(p));
  }
  for (int i = 0; i + step < s.num_frames; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    absl::StatusOr<plx::OdometryResult> r = plx::EstimateOdometry(
        pyramids[i], pyramids[i + step], plx::SE3::Identity(), plx::OdometryOptions());
    align_ms.push_back(Millis(t0, std::chrono::steady_clock::now()));
    if (!r.ok()) return 1;
    not_ok += !r->ok;
    const plx::RgbdFrame& a = seq->frames()[i];
    const plx::RgbdFrame& b = seq->frames()[i + step];
    const plx::SE3 error =
        (a.ground_truth->Inverse() * *b.ground_truth).Inverse() * r->reference_T_current;
    error_cm.push_back(100 * error.translation().norm());
    error_deg.push_back(Eigen::AngleAxisd(error.rotation()).angle() * 180 / M_PI);
  }
  std::printf("odometry %dx%d, %zu pairs (frame i to i+%d), identity start\n", s.width,
              s.height, align_ms.size(), step);
  std::printf("  pyramid ms: median %.1f, max %.1f\n", Median(pyramid_ms), Max(pyramid_ms));
  std::printf("  align ms:   median %.1f, max %.1f\n", Median(align_ms), Max(align_ms));
  std::printf("  error cm:   median %.3f, max %.3f\n", Median(error_cm), Max(error_cm));
  std::printf("  error deg:  median %.3f, max %.3f\n", Median(error_deg), Max(error_deg));
  std::printf("  not ok:     %d\n", not_ok);
  return 0;
}

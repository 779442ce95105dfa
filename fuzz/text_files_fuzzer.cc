// The text files a user hands plenox and plenoxd's tools: TUM trajectories (--gt, --est, a
// dataset's groundtruth.txt through ReadTumTrajectory), intrinsics.txt, ScanNet's camera matrix
// files, and the one-line pose and intrinsics flags (--pose, --intrinsics). The input is one
// file; every reader gets it, and what a reader accepts is written back with the project's
// writer and read again (the writers promise files their readers take back).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/formats/calibration_file.h"
#include "core/formats/pose_text.h"
#include "core/formats/text_table.h"
#include "core/formats/trajectory_file.h"
#include "core/geometry/intrinsics.h"
#include "fuzz/fuzz_util.h"

namespace {

bool IsUnit(const plx::SE3& pose) { return std::abs(pose.rotation().norm() - 1.0) < 1e-9; }

void Trajectory(const std::string& path) {
  const absl::StatusOr<std::vector<plx::StampedPose>> poses = plx::ReadTumTrajectory(path);
  if (!poses.ok()) return;
  for (size_t i = 0; i < poses->size(); ++i) {
    const plx::StampedPose& p = (*poses)[i];
    PLX_FUZZ_CHECK(std::isfinite(p.timestamp) && p.pose.translation().allFinite(),
                   "non-finite pose read");
    PLX_FUZZ_CHECK(IsUnit(p.pose), "trajectory rotation is not a unit quaternion");
    PLX_FUZZ_CHECK(i == 0 || (*poses)[i - 1].timestamp < p.timestamp, "not strictly sorted");
  }
  // The writer refuses stamps closer than its 1 us precision; what it writes must read back.
  const std::string again = plx::fuzz::ScratchPath("again.txt");
  if (!plx::WriteTumTrajectory(again, *poses, "fuzz").ok()) return;
  const absl::StatusOr<std::vector<plx::StampedPose>> reread = plx::ReadTumTrajectory(again);
  PLX_FUZZ_CHECK(reread.ok(), reread.status().ToString());
  PLX_FUZZ_CHECK(reread->size() == poses->size(), "pose count after a round trip");
}

void Calibration(const std::string& path) {
  const absl::StatusOr<plx::CameraCalibration> c = plx::ReadCalibrationFile(path);
  if (!c.ok()) return;
  PLX_FUZZ_CHECK(plx::ValidateCalibration(*c).ok(), "read an invalid calibration");
  // FormatCalibrationFile prints the shortest text that parses back exactly.
  const std::string again = plx::fuzz::ScratchPath("again_intrinsics.txt");
  PLX_FUZZ_CHECK(plx::WriteCalibrationFile(again, *c).ok(), "cannot write calibration");
  const absl::StatusOr<plx::CameraCalibration> d = plx::ReadCalibrationFile(again);
  PLX_FUZZ_CHECK(d.ok(), d.status().ToString());
  PLX_FUZZ_CHECK(plx::FormatCalibrationFile(*d) == plx::FormatCalibrationFile(*c),
                 "calibration changed in a round trip");
}

void PoseText(const std::string& text) {
  const absl::StatusOr<plx::SE3> pose = plx::ParsePoseText(text);
  if (!pose.ok()) return;
  PLX_FUZZ_CHECK(IsUnit(*pose), "pose text rotation is not a unit quaternion");
  const absl::StatusOr<plx::SE3> again = plx::ParsePoseText(plx::FormatPoseText(*pose));
  PLX_FUZZ_CHECK(again.ok(), again.status().ToString());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string path = plx::fuzz::ScratchPath("in.txt");
  plx::fuzz::WriteFileOrDie(path, text);

  plx::ReadTextTable(path).IgnoreError();
  Trajectory(path);
  Calibration(path);
  const absl::StatusOr<plx::PinholeIntrinsics> matrix = plx::ReadIntrinsicMatrixFile(path);
  if (matrix.ok()) {
    PLX_FUZZ_CHECK(std::isfinite(matrix->fx) && std::isfinite(matrix->fy) &&
                       std::isfinite(matrix->cx) && std::isfinite(matrix->cy),
                   "camera matrix with non-finite entries");
  }
  PoseText(text);
  const absl::StatusOr<plx::PinholeIntrinsics> flag = plx::ParsePinholeIntrinsics(text);
  if (flag.ok()) {
    PLX_FUZZ_CHECK(flag->width > 0 && flag->height > 0, "intrinsics flag with a zero size");
  }
  return 0;
}

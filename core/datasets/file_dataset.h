// The part every on-disk layout (TUM, Replica, ScanNet) shares once its index has been parsed:
// a list of image file pairs with timestamps and optional ground truth, decoded lazily.
// Each layout's reader only turns its files into a FrameFiles list and a calibration.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/datasets/dataset.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/io/image_io.h"

namespace plx {

struct FrameFiles {
  double timestamp = 0.0;
  std::string color_path;
  std::string depth_path;
  std::optional<SE3> ground_truth;  // world_T_camera from the dataset's pose files
};

class FileDataset final : public RgbdDataset {
 public:
  // `calibration` is the sensor's (possibly distorted) one; frames come out undistorted.
  // With `resize_color_to_depth` a colour image of another size is resized (area averaging) to
  // the depth image's size before the size checks (ScanNet's 1296x968 colour, 640x480 depth).
  // Errors: invalid calibration, no frames.
  static absl::StatusOr<std::unique_ptr<FileDataset>> Create(std::string name,
                                                             const CameraCalibration& calibration,
                                                             std::vector<FrameFiles> frames,
                                                             bool resize_color_to_depth = false);

  std::string name() const override { return name_; }
  const CameraCalibration& calibration() const override { return calibration_; }
  int size() const override { return static_cast<int>(frames_.size()); }
  // NaN / nullopt for an index out of range (the interface has no Status here).
  double timestamp(int index) const override;
  std::optional<SE3> ground_truth(int index) const override;
  absl::StatusOr<RgbdFrame> LoadFrame(int index) const override;

 private:
  FileDataset(std::string name, CameraCalibration calibration, double depth_scale,
              std::optional<Undistorter> undistorter, std::vector<FrameFiles> frames,
              bool resize_color_to_depth);

  std::string name_;
  CameraCalibration calibration_;  // what frames are delivered in: distortion is zero
  double depth_scale_;
  std::optional<Undistorter> undistorter_;  // set when the sensor calibration has distortion
  std::vector<FrameFiles> frames_;
  bool resize_color_to_depth_;
};

// Helpers shared by the layout readers.

// NotFoundError unless `directory` is an existing directory.
absl::Status CheckDatasetDirectory(const std::string& directory);

// The sequence's name: the last component of `directory` ("tum_fr3_teddy").
std::string DatasetNameFromDirectory(const std::string& directory);

// `relative` inside `directory` (an absolute `relative` stays as it is).
std::string JoinPath(const std::string& directory, const std::string& relative);

// NotFoundError "<path>: image not found (listed in <listed_in>)" when `path` is not a file.
absl::Status CheckImageExists(const std::string& path, absl::string_view listed_in);

// Files in `directory` named <prefix><integer><extension> for one of `extensions` (lower
// case, with the dot; matched case-insensitively), keyed by the integer; other files are
// ignored. Errors when the directory cannot be listed or two files share a number.
absl::StatusOr<std::map<int64_t, std::string>> ListNumberedFiles(
    const std::string& directory, absl::string_view prefix,
    const std::vector<std::string>& extensions);

// A 4x4 camera-to-world matrix as an SE3. The bottom row must be 0 0 0 1 and the rotation
// close to orthonormal; it is then re-orthonormalised (nearest rotation, by SVD) so that small
// rounding in text files does not leak a scale or shear into the pose. The error message has
// no location: callers prefix the file and line.
absl::StatusOr<SE3> PoseFromMatrix(const Eigen::Matrix4d& matrix);

}  // namespace plx

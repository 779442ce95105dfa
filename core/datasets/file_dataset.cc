#include "core/datasets/file_dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <system_error>
#include <utility>

#include <Eigen/SVD>
#include <opencv2/imgproc.hpp>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace plx {

absl::StatusOr<std::unique_ptr<FileDataset>> FileDataset::Create(
    std::string name, const CameraCalibration& calibration, std::vector<FrameFiles> frames,
    bool resize_color_to_depth) {
  if (absl::Status status = ValidateCalibration(calibration); !status.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": invalid calibration: ", status.message()));
  }
  if (frames.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": the dataset has no frames"));
  }
  std::optional<Undistorter> undistorter;
  CameraCalibration delivered = calibration;
  if (!calibration.distortion.IsZero()) {
    PLX_ASSIGN_OR_RETURN(Undistorter maps, Undistorter::Create(calibration));
    undistorter = std::move(maps);
    delivered.distortion = Distortion{};
  }
  return std::unique_ptr<FileDataset>(
      new FileDataset(std::move(name), delivered, calibration.depth_scale, std::move(undistorter),
                      std::move(frames), resize_color_to_depth));
}

FileDataset::FileDataset(std::string name, CameraCalibration calibration, double depth_scale,
                         std::optional<Undistorter> undistorter, std::vector<FrameFiles> frames,
                         bool resize_color_to_depth)
    : name_(std::move(name)),
      calibration_(calibration),
      depth_scale_(depth_scale),
      undistorter_(std::move(undistorter)),
      frames_(std::move(frames)),
      resize_color_to_depth_(resize_color_to_depth) {}

double FileDataset::timestamp(int index) const {
  if (index < 0 || index >= size()) return std::numeric_limits<double>::quiet_NaN();
  return frames_[index].timestamp;
}

std::optional<SE3> FileDataset::ground_truth(int index) const {
  if (index < 0 || index >= size()) return std::nullopt;
  return frames_[index].ground_truth;
}

absl::StatusOr<RgbdFrame> FileDataset::LoadFrame(int index) const {
  if (index < 0 || index >= size()) {
    return absl::OutOfRangeError(
        absl::StrCat(name_, ": frame ", index, " out of range [0, ", size(), ")"));
  }
  const FrameFiles& files = frames_[index];
  PLX_ASSIGN_OR_RETURN(cv::Mat color, DecodeColorFile(files.color_path));
  PLX_ASSIGN_OR_RETURN(cv::Mat depth, DecodeDepthFile(files.depth_path));

  if (resize_color_to_depth_ && color.size() != depth.size()) {
    cv::Mat resized;
    try {
      cv::resize(color, resized, depth.size(), 0, 0, cv::INTER_AREA);
    } catch (const cv::Exception& e) {
      return absl::InvalidArgumentError(
          absl::StrCat(files.color_path, ": resizing to the depth size failed: ", e.what()));
    }
    color = std::move(resized);
  }
  if (color.size() != depth.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat(name_, " frame ", index, ": colour image ", files.color_path, " is ",
                     SizeString(color.cols, color.rows), " but depth image ", files.depth_path,
                     " is ", SizeString(depth.cols, depth.rows)));
  }
  const PinholeIntrinsics& k = calibration_.pinhole;
  if (depth.cols != k.width || depth.rows != k.height) {
    return absl::InvalidArgumentError(absl::StrCat(name_, " frame ", index, ": images ",
                                                   files.color_path, " and ", files.depth_path,
                                                   " are ", SizeString(depth.cols, depth.rows),
                                                   " but the calibration (intrinsics.txt or "
                                                   "flags) is for ",
                                                   SizeString(k.width, k.height)));
  }
  if (undistorter_.has_value()) {
    PLX_ASSIGN_OR_RETURN(color, undistorter_->UndistortColor(color));
    PLX_ASSIGN_OR_RETURN(depth, undistorter_->UndistortDepth(depth));
  }

  RgbdFrame frame;
  frame.timestamp = files.timestamp;
  frame.color = ColorImageFromMat(color);
  frame.depth = DepthImageFromMat(depth, depth_scale_);
  frame.ground_truth = files.ground_truth;
  return frame;
}

absl::Status CheckDatasetDirectory(const std::string& directory) {
  std::error_code ec;
  if (!std::filesystem::is_directory(directory, ec)) {
    return absl::NotFoundError(absl::StrCat(directory, ": dataset directory not found"));
  }
  return absl::OkStatus();
}

std::string DatasetNameFromDirectory(const std::string& directory) {
  std::filesystem::path path = std::filesystem::path(directory).lexically_normal();
  // "data/seq/" normalises to "data/seq/" whose filename() is empty.
  if (!path.has_filename() && path.has_parent_path()) path = path.parent_path();
  std::string name = path.filename().string();
  return name.empty() || name == "." ? directory : name;
}

std::string JoinPath(const std::string& directory, const std::string& relative) {
  return (std::filesystem::path(directory) / relative).string();
}

absl::Status CheckImageExists(const std::string& path, absl::string_view listed_in) {
  std::error_code ec;
  if (std::filesystem::is_regular_file(path, ec)) return absl::OkStatus();
  return absl::NotFoundError(absl::StrCat(path, ": image not found (listed in ", listed_in, ")"));
}

absl::StatusOr<std::map<int64_t, std::string>> ListNumberedFiles(
    const std::string& directory, absl::string_view prefix,
    const std::vector<std::string>& extensions) {
  namespace fs = std::filesystem;
  std::map<int64_t, std::string> files;
  std::error_code ec;
  fs::directory_iterator it(directory, ec);
  if (ec) {
    return absl::NotFoundError(absl::StrCat(directory, ": cannot list directory: ", ec.message()));
  }
  for (; it != fs::directory_iterator(); it.increment(ec)) {
    if (ec) {
      return absl::DataLossError(absl::StrCat(directory, ": listing failed: ", ec.message()));
    }
    const fs::path& path = it->path();
    const std::string extension = absl::AsciiStrToLower(path.extension().string());
    if (std::find(extensions.begin(), extensions.end(), extension) == extensions.end()) continue;
    const std::string stem = path.stem().string();
    if (!absl::StartsWith(stem, prefix)) continue;
    const absl::string_view digits = absl::string_view(stem).substr(prefix.size());
    if (digits.empty() || !std::all_of(digits.begin(), digits.end(), absl::ascii_isdigit)) {
      continue;
    }
    int64_t number = 0;
    if (!absl::SimpleAtoi(digits, &number)) continue;
    const auto [existing, inserted] = files.emplace(number, path.string());
    if (!inserted) {
      return absl::InvalidArgumentError(absl::StrCat("two files for frame ", number, ": ",
                                                     existing->second, " and ", path.string()));
    }
  }
  if (ec) return absl::DataLossError(absl::StrCat(directory, ": listing failed: ", ec.message()));
  return files;
}

absl::StatusOr<SE3> PoseFromMatrix(const Eigen::Matrix4d& matrix) {
  if (!matrix.allFinite()) return absl::InvalidArgumentError("pose matrix is not finite");
  constexpr double kBottomRowTolerance = 1e-6;
  if ((matrix.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() >
      kBottomRowTolerance) {
    return absl::InvalidArgumentError("the last row of a pose matrix must be 0 0 0 1");
  }
  const Eigen::Matrix3d rotation = matrix.topLeftCorner<3, 3>();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(rotation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d nearest = svd.matrixU() * svd.matrixV().transpose();
  if (nearest.determinant() < 0) {
    return absl::InvalidArgumentError("pose rotation is a reflection (determinant < 0)");
  }
  // Text files round to a few decimals (TUM: 4); anything much worse is not a rotation.
  constexpr double kOrthonormalTolerance = 1e-2;
  if ((rotation - nearest).cwiseAbs().maxCoeff() > kOrthonormalTolerance) {
    return absl::InvalidArgumentError("pose rotation is not orthonormal");
  }
  return SE3(nearest, Eigen::Vector3d(matrix.topRightCorner<3, 1>()));
}

}  // namespace plx

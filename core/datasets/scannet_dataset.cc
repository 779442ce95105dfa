#include "core/datasets/scannet_dataset.h"

#include <filesystem>
#include <map>
#include <optional>
#include <system_error>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/datasets/file_dataset.h"
#include "core/formats/calibration_file.h"
#include "core/formats/text_table.h"
#include "core/io/image_io.h"

namespace plx {
namespace {

constexpr char kColorDir[] = "color";
constexpr char kDepthDir[] = "depth";
constexpr char kPoseDir[] = "pose";
constexpr char kDepthIntrinsicFile[] = "intrinsic/intrinsic_depth.txt";
constexpr double kScanNetDepthScale = 1000.0;  // millimetres
constexpr double kFrameRate = 30.0;            // the Structure sensor's rate

bool IsDirectory(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_directory(path, ec);
}

bool IsFile(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

// nullopt for ScanNet's "tracking lost" poses (rows of -inf / nan).
absl::StatusOr<std::optional<SE3>> ReadPoseFile(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  if (table.rows.size() != 4) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": expected a 4x4 matrix (4 rows), got ", table.rows.size(), " rows"));
  }
  Eigen::Matrix4d matrix;
  for (int r = 0; r < 4; ++r) {
    const TextRow& row = table.rows[r];
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, row, 4, "numbers"));
    PLX_ASSIGN_OR_RETURN(const std::vector<double> values,
                         ParseDoubleFields(table, row, 0, 4, /*allow_non_finite=*/true));
    for (int c = 0; c < 4; ++c) matrix(r, c) = values[c];
  }
  if (!matrix.allFinite()) return std::optional<SE3>();
  absl::StatusOr<SE3> pose = PoseFromMatrix(matrix);
  if (!pose.ok()) return LineError(path, table.rows[0].line_number, pose.status().message());
  return std::optional<SE3>(*pose);
}

absl::StatusOr<CameraCalibration> LoadScanNetCalibration(const std::string& directory,
                                                         const DatasetOptions& options,
                                                         const std::string& first_depth) {
  if (options.calibration.has_value() || IsFile(JoinPath(directory, kCalibrationFileName))) {
    return LoadDatasetCalibration(directory, options.calibration);
  }
  const std::string matrix_path = JoinPath(directory, kDepthIntrinsicFile);
  if (!IsFile(matrix_path)) {
    const absl::Status missing = MissingCalibrationError(directory);
    return absl::NotFoundError(
        absl::StrCat(missing.message(), "; ", kDepthIntrinsicFile, " is missing too"));
  }
  CameraCalibration calibration;
  PLX_ASSIGN_OR_RETURN(calibration.pinhole, ReadIntrinsicMatrixFile(matrix_path));
  calibration.depth_scale = kScanNetDepthScale;
  // The matrix file has no image size; the depth images define it.
  PLX_ASSIGN_OR_RETURN(const cv::Mat depth, DecodeDepthFile(first_depth));
  calibration.pinhole.width = depth.cols;
  calibration.pinhole.height = depth.rows;
  if (absl::Status status = ValidateCalibration(calibration); !status.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(matrix_path, ": ", status.message()));
  }
  return calibration;
}

}  // namespace

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenScanNetDataset(const std::string& directory,
                                                                const DatasetOptions& options) {
  PLX_RETURN_IF_ERROR(CheckDatasetDirectory(directory));
  const std::string color_dir = JoinPath(directory, kColorDir);
  const std::string depth_dir = JoinPath(directory, kDepthDir);
  const std::string pose_dir = JoinPath(directory, kPoseDir);
  for (const std::string& dir : {color_dir, depth_dir}) {
    if (!IsDirectory(dir)) {
      return absl::NotFoundError(absl::StrCat(dir, ": ScanNet folder not found"));
    }
  }
  PLX_ASSIGN_OR_RETURN(const auto colors,
                       ListNumberedFiles(color_dir, "", {".jpg", ".jpeg", ".png"}));
  PLX_ASSIGN_OR_RETURN(const auto depths, ListNumberedFiles(depth_dir, "", {".png"}));
  // Without pose/ at all (ScanNet's test scenes) frames simply have no ground truth; with it,
  // a missing file means a broken export.
  const bool has_poses = IsDirectory(pose_dir);
  std::map<int64_t, std::string> pose_files;
  if (has_poses) {
    PLX_ASSIGN_OR_RETURN(pose_files, ListNumberedFiles(pose_dir, "", {".txt"}));
  }
  if (colors.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(color_dir, ": no frames (expected <i>.jpg with depth/<i>.png)"));
  }

  std::vector<FrameFiles> frames;
  frames.reserve(colors.size());
  for (const auto& [number, color_path] : colors) {
    const auto depth = depths.find(number);
    if (depth == depths.end()) {
      return absl::NotFoundError(absl::StrCat(JoinPath(depth_dir, absl::StrCat(number, ".png")),
                                              ": depth image not found for ", color_path));
    }
    FrameFiles frame;
    frame.timestamp = static_cast<double>(number) / kFrameRate;
    frame.color_path = color_path;
    frame.depth_path = depth->second;
    if (has_poses) {
      const auto pose = pose_files.find(number);
      if (pose == pose_files.end()) {
        return absl::NotFoundError(absl::StrCat(JoinPath(pose_dir, absl::StrCat(number, ".txt")),
                                                ": pose file not found for ", color_path));
      }
      PLX_ASSIGN_OR_RETURN(frame.ground_truth, ReadPoseFile(pose->second));
    }
    frames.push_back(std::move(frame));
  }

  PLX_ASSIGN_OR_RETURN(const CameraCalibration calibration,
                       LoadScanNetCalibration(directory, options, frames.front().depth_path));
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<FileDataset> dataset,
                       FileDataset::Create(DatasetNameFromDirectory(directory), calibration,
                                           std::move(frames), /*resize_color_to_depth=*/true));
  return std::unique_ptr<RgbdDataset>(std::move(dataset));
}

}  // namespace plx

#include "core/datasets/replica_dataset.h"

#include <filesystem>
#include <map>
#include <system_error>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/datasets/file_dataset.h"
#include "core/formats/calibration_file.h"
#include "core/formats/text_table.h"

namespace plx {
namespace {

constexpr char kResultsDir[] = "results";
constexpr char kTrajectoryFile[] = "traj.txt";
// Replica renders have no clock; 30 Hz is the rate NICE-SLAM and followers assume.
constexpr double kFrameRate = 30.0;

absl::StatusOr<std::vector<SE3>> ReadTrajectory(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  std::vector<SE3> poses;
  poses.reserve(table.rows.size());
  for (const TextRow& row : table.rows) {
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, row, 16, "numbers (a row-major 4x4 matrix)"));
    PLX_ASSIGN_OR_RETURN(const std::vector<double> v, ParseDoubleFields(table, row, 0, 16));
    const Eigen::Matrix4d matrix =
        Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(v.data());
    absl::StatusOr<SE3> pose = PoseFromMatrix(matrix);
    if (!pose.ok()) return LineError(table.path, row.line_number, pose.status().message());
    poses.push_back(*pose);
  }
  return poses;
}

}  // namespace

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenReplicaDataset(const std::string& directory,
                                                                const DatasetOptions& options) {
  PLX_RETURN_IF_ERROR(CheckDatasetDirectory(directory));
  const std::string results = JoinPath(directory, kResultsDir);
  std::error_code ec;
  if (!std::filesystem::is_directory(results, ec)) {
    return absl::NotFoundError(absl::StrCat(results, ": Replica image folder not found"));
  }
  PLX_ASSIGN_OR_RETURN(const CameraCalibration calibration,
                       LoadDatasetCalibration(directory, options.calibration));

  PLX_ASSIGN_OR_RETURN(const auto colors, ListNumberedFiles(results, "frame", {".jpg", ".png"}));
  PLX_ASSIGN_OR_RETURN(const auto depths, ListNumberedFiles(results, "depth", {".png"}));
  if (colors.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(results, ": no frames (expected frame%06d.jpg and depth%06d.png)"));
  }
  for (const auto& [number, path] : colors) {
    if (!depths.contains(number)) {
      return absl::NotFoundError(absl::StrCat(results, ": no depth image depth<n>.png for ", path));
    }
  }
  for (const auto& [number, path] : depths) {
    if (!colors.contains(number)) {
      return absl::NotFoundError(
          absl::StrCat(results, ": no colour image frame<n>.jpg/.png for ", path));
    }
  }

  const std::string trajectory_path = JoinPath(directory, kTrajectoryFile);
  PLX_ASSIGN_OR_RETURN(const std::vector<SE3> poses, ReadTrajectory(trajectory_path));
  if (poses.size() != colors.size()) {
    return absl::InvalidArgumentError(absl::StrCat(trajectory_path, ": has ", poses.size(),
                                                   " poses but ", results, " has ", colors.size(),
                                                   " frames; traj.txt needs one line per frame"));
  }

  std::vector<FrameFiles> frames;
  frames.reserve(colors.size());
  for (const auto& [number, color_path] : colors) {
    FrameFiles frame;
    frame.timestamp = static_cast<double>(number) / kFrameRate;
    frame.color_path = color_path;
    frame.depth_path = depths.find(number)->second;
    frame.ground_truth = poses[frames.size()];
    frames.push_back(std::move(frame));
  }
  PLX_ASSIGN_OR_RETURN(
      std::unique_ptr<FileDataset> dataset,
      FileDataset::Create(DatasetNameFromDirectory(directory), calibration, std::move(frames)));
  return std::unique_ptr<RgbdDataset>(std::move(dataset));
}

}  // namespace plx

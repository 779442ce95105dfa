#include "core/datasets/dataset.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <system_error>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/datasets/file_dataset.h"
#include "core/datasets/replica_dataset.h"
#include "core/datasets/scannet_dataset.h"
#include "core/datasets/tum_dataset.h"
#include "core/formats/calibration_file.h"
#include "core/formats/text_table.h"
#include "core/io/atomic_write.h"
#include "core/io/image_io.h"

namespace plx {
namespace {

bool Exists(const std::string& directory, const char* name, bool want_directory) {
  std::error_code ec;
  const std::filesystem::path path = std::filesystem::path(directory) / name;
  return want_directory ? std::filesystem::is_directory(path, ec)
                        : std::filesystem::is_regular_file(path, ec);
}

absl::StatusOr<DatasetFormat> DetectFormat(const std::string& directory) {
  if (Exists(directory, "rgb.txt", false) || Exists(directory, "associations.txt", false)) {
    return DatasetFormat::kTum;
  }
  if (Exists(directory, "results", true) && Exists(directory, "traj.txt", false)) {
    return DatasetFormat::kReplica;
  }
  if (Exists(directory, "color", true) && Exists(directory, "depth", true) &&
      Exists(directory, "pose", true)) {
    return DatasetFormat::kScanNet;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      directory,
      ": cannot tell the dataset layout; looked for rgb.txt or associations.txt "
      "(TUM), results/ with traj.txt (Replica), color/ depth/ pose/ (ScanNet). Pass the "
      "format explicitly if the layout is one of these"));
}

absl::Status CheckFrameShape(const RgbdFrame& frame, int index, const PinholeIntrinsics& k) {
  const bool color_ok = frame.color.channels == 3 && frame.color.width == k.width &&
                        frame.color.height == k.height &&
                        frame.color.data.size() == static_cast<size_t>(k.width) * k.height * 3;
  const bool depth_ok = frame.depth.channels == 1 && frame.depth.width == k.width &&
                        frame.depth.height == k.height &&
                        frame.depth.data.size() == static_cast<size_t>(k.width) * k.height;
  if (color_ok && depth_ok) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "frame ", index, ": colour is ", SizeString(frame.color.width, frame.color.height), "x",
      frame.color.channels, ", depth is ", SizeString(frame.depth.width, frame.depth.height), "x",
      frame.depth.channels, "; the calibration needs ", SizeString(k.width, k.height),
      " with 3 and 1 channels"));
}

// "timestamp tx ty tz qx qy qz qw" with qw >= 0 (q and -q are the same rotation).
std::string GroundTruthLine(const std::string& stamp, const SE3& pose) {
  Eigen::Quaterniond q = pose.rotation();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d& t = pose.translation();
  return absl::StrCat(stamp, " ", FormatShortest(t.x()), " ", FormatShortest(t.y()), " ",
                      FormatShortest(t.z()), " ", FormatShortest(q.x()), " ", FormatShortest(q.y()),
                      " ", FormatShortest(q.z()), " ", FormatShortest(q.w()), "\n");
}

}  // namespace

absl::StatusOr<DatasetFormat> ParseDatasetFormat(const std::string& name) {
  const std::string lower = absl::AsciiStrToLower(name);
  if (lower == "auto") return DatasetFormat::kAuto;
  if (lower == "tum") return DatasetFormat::kTum;
  if (lower == "replica") return DatasetFormat::kReplica;
  if (lower == "scannet") return DatasetFormat::kScanNet;
  return absl::InvalidArgumentError(absl::StrCat("unknown dataset format \"", name,
                                                 "\"; expected auto, tum, replica or scannet"));
}

const char* DatasetFormatName(DatasetFormat format) {
  switch (format) {
    case DatasetFormat::kAuto:
      return "auto";
    case DatasetFormat::kTum:
      return "tum";
    case DatasetFormat::kReplica:
      return "replica";
    case DatasetFormat::kScanNet:
      return "scannet";
  }
  return "unknown";
}

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenDataset(const std::string& directory,
                                                         const DatasetOptions& options) {
  PLX_RETURN_IF_ERROR(CheckDatasetDirectory(directory));
  DatasetFormat format = options.format;
  if (format == DatasetFormat::kAuto) {
    PLX_ASSIGN_OR_RETURN(format, DetectFormat(directory));
  }
  switch (format) {
    case DatasetFormat::kTum:
      return OpenTumDataset(directory, options);
    case DatasetFormat::kReplica:
      return OpenReplicaDataset(directory, options);
    case DatasetFormat::kScanNet:
      return OpenScanNetDataset(directory, options);
    case DatasetFormat::kAuto:
      break;
  }
  return absl::InternalError("unreachable dataset format");
}

absl::Status WriteTumDataset(const RgbdDataset& dataset, const std::string& directory) {
  const CameraCalibration& calibration = dataset.calibration();
  if (absl::Status status = ValidateCalibration(calibration); !status.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write ", dataset.name(), ": ", status.message()));
  }
  if (dataset.size() <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write ", dataset.name(), ": it has no frames"));
  }
  namespace fs = std::filesystem;
  const fs::path root(directory);
  for (const fs::path& dir : {root, root / "rgb", root / "depth"}) {
    std::error_code create_error, check_error;
    fs::create_directories(dir, create_error);
    if (!fs::is_directory(dir, check_error)) {
      return absl::PermissionDeniedError(
          absl::StrCat(dir.string(), ": cannot create directory: ", create_error.message()));
    }
  }

  std::string rgb_list = "# color images\n# timestamp filename\n";
  std::string depth_list = "# depth maps\n# timestamp filename\n";
  std::string associations;
  std::string ground_truth = "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n";
  std::map<std::string, int> stamps;  // file names must not collide
  for (int i = 0; i < dataset.size(); ++i) {
    const double t = dataset.timestamp(i);
    if (!std::isfinite(t)) {
      return absl::InvalidArgumentError(absl::StrCat("frame ", i, ": timestamp is not finite"));
    }
    const std::string stamp = absl::StrFormat("%.6f", t);
    if (const auto [it, inserted] = stamps.emplace(stamp, i); !inserted) {
      return absl::InvalidArgumentError(
          absl::StrCat("frames ", it->second, " and ", i, " have the same timestamp ", stamp,
                       " to the microsecond; TUM file names would collide"));
    }
    PLX_ASSIGN_OR_RETURN(const RgbdFrame frame, dataset.LoadFrame(i));
    PLX_RETURN_IF_ERROR(CheckFrameShape(frame, i, calibration.pinhole));
    const std::string rgb_name = absl::StrCat("rgb/", stamp, ".png");
    const std::string depth_name = absl::StrCat("depth/", stamp, ".png");
    PLX_RETURN_IF_ERROR(WriteColorImage((root / rgb_name).string(), frame.color));
    PLX_RETURN_IF_ERROR(
        WriteDepthImage((root / depth_name).string(), frame.depth, calibration.depth_scale));
    absl::StrAppend(&rgb_list, stamp, " ", rgb_name, "\n");
    absl::StrAppend(&depth_list, stamp, " ", depth_name, "\n");
    absl::StrAppend(&associations, stamp, " ", rgb_name, " ", stamp, " ", depth_name, "\n");
    if (const std::optional<SE3> pose = dataset.ground_truth(i); pose.has_value()) {
      absl::StrAppend(&ground_truth, GroundTruthLine(stamp, *pose));
    }
  }
  PLX_RETURN_IF_ERROR(WriteFilesAtomically(
      {{(root / "rgb.txt").string(), rgb_list},
       {(root / "depth.txt").string(), depth_list},
       {(root / "associations.txt").string(), associations},
       {(root / "groundtruth.txt").string(), ground_truth}},
      absl::StrCat("cannot write the dataset's lists to ", directory)));
  return WriteCalibrationFile((root / kCalibrationFileName).string(), calibration);
}

}  // namespace plx

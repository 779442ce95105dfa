#include "core/datasets/tum_dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <system_error>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/datasets/file_dataset.h"
#include "core/formats/calibration_file.h"
#include "core/formats/text_table.h"

namespace plx {
namespace {

constexpr char kAssociationsFile[] = "associations.txt";
constexpr char kRgbListFile[] = "rgb.txt";
constexpr char kDepthListFile[] = "depth.txt";
constexpr char kGroundTruthFile[] = "groundtruth.txt";

// One line of rgb.txt / depth.txt.
struct StampedFile {
  double timestamp = 0.0;
  std::string path;
  std::string listed_at;  // "file:line", for the missing-image error
};

std::string Location(const TextTable& table, const TextRow& row) {
  return absl::StrCat(table.path, ":", row.line_number);
}

bool FileExists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::exists(path, ec);
}

absl::StatusOr<std::vector<StampedFile>> ReadFileList(const std::string& directory,
                                                      const char* name) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(JoinPath(directory, name)));
  std::vector<StampedFile> files;
  files.reserve(table.rows.size());
  for (const TextRow& row : table.rows) {
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, row, 2, "fields \"timestamp filename\""));
    PLX_ASSIGN_OR_RETURN(const double t, ParseDoubleField(table, row, 0));
    files.push_back({t, JoinPath(directory, row.fields[1]), Location(table, row)});
  }
  return files;
}

// associations.txt: the pairing is given, nothing to match.
absl::StatusOr<std::vector<FrameFiles>> ReadAssociations(const std::string& directory) {
  PLX_ASSIGN_OR_RETURN(const TextTable table,
                       ReadTextTable(JoinPath(directory, kAssociationsFile)));
  std::vector<FrameFiles> frames;
  frames.reserve(table.rows.size());
  for (const TextRow& row : table.rows) {
    PLX_RETURN_IF_ERROR(
        ExpectFieldCount(table, row, 4, "fields \"t_rgb rgb_file t_depth depth_file\""));
    PLX_ASSIGN_OR_RETURN(const double t_rgb, ParseDoubleField(table, row, 0));
    PLX_RETURN_IF_ERROR(ParseDoubleField(table, row, 2).status());
    FrameFiles frame;
    frame.timestamp = t_rgb;
    frame.color_path = JoinPath(directory, row.fields[1]);
    frame.depth_path = JoinPath(directory, row.fields[3]);
    PLX_RETURN_IF_ERROR(CheckImageExists(frame.color_path, Location(table, row)));
    PLX_RETURN_IF_ERROR(CheckImageExists(frame.depth_path, Location(table, row)));
    frames.push_back(std::move(frame));
  }
  if (frames.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(table.path, ": lists no frames"));
  }
  return frames;
}

// rgb.txt + depth.txt matched by timestamp.
absl::StatusOr<std::vector<FrameFiles>> AssociateFileLists(const std::string& directory,
                                                           double max_time_difference) {
  PLX_ASSIGN_OR_RETURN(const std::vector<StampedFile> rgb, ReadFileList(directory, kRgbListFile));
  PLX_ASSIGN_OR_RETURN(const std::vector<StampedFile> depth,
                       ReadFileList(directory, kDepthListFile));
  std::vector<double> rgb_times, depth_times;
  for (const StampedFile& f : rgb) rgb_times.push_back(f.timestamp);
  for (const StampedFile& f : depth) depth_times.push_back(f.timestamp);
  const std::vector<std::pair<int, int>> pairs =
      AssociateTimestamps(rgb_times, depth_times, max_time_difference);
  if (pairs.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(directory, ": no colour/depth pairs within ", max_time_difference,
                     " s between ", kRgbListFile, " (", rgb.size(), " entries) and ",
                     kDepthListFile, " (", depth.size(), " entries)"));
  }
  std::vector<FrameFiles> frames;
  frames.reserve(pairs.size());
  for (const auto& [i, j] : pairs) {
    PLX_RETURN_IF_ERROR(CheckImageExists(rgb[i].path, rgb[i].listed_at));
    PLX_RETURN_IF_ERROR(CheckImageExists(depth[j].path, depth[j].listed_at));
    FrameFiles frame;
    frame.timestamp = rgb[i].timestamp;
    frame.color_path = rgb[i].path;
    frame.depth_path = depth[j].path;
    frames.push_back(std::move(frame));
  }
  return frames;
}

absl::StatusOr<std::vector<StampedPose>> ReadGroundTruth(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  std::vector<StampedPose> samples;
  samples.reserve(table.rows.size());
  for (const TextRow& row : table.rows) {
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, row, 8, "numbers"));
    PLX_ASSIGN_OR_RETURN(const std::vector<double> v, ParseDoubleFields(table, row, 0, 8));
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);  // file order: qx qy qz qw
    // The file rounds to a few decimals; a norm far from 1 means a broken or misordered line.
    if (std::abs(q.norm() - 1.0) > 1e-2) {
      return LineError(
          table.path, row.line_number,
          absl::StrCat("quaternion qx qy qz qw must have unit length, got norm ", q.norm()));
    }
    samples.push_back({v[0], SE3(q, Eigen::Vector3d(v[1], v[2], v[3]))});
  }
  std::stable_sort(samples.begin(), samples.end(), [](const StampedPose& a, const StampedPose& b) {
    return a.timestamp < b.timestamp;
  });
  return samples;
}

}  // namespace

std::vector<std::pair<int, int>> AssociateTimestamps(const std::vector<double>& first,
                                                     const std::vector<double>& second,
                                                     double max_difference) {
  // Candidate pairs come from a window search in the sorted second list, so this stays
  // O(n log n) on full-length TUM sequences rather than associate.py's all-pairs loop.
  std::vector<int> order(second.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return second[a] < second[b]; });
  std::vector<double> sorted;
  sorted.reserve(order.size());
  for (int j : order) sorted.push_back(second[j]);

  std::vector<std::tuple<double, int, int>> candidates;  // (|difference|, first, second)
  for (int i = 0; i < static_cast<int>(first.size()); ++i) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), first[i] - max_difference);
    for (; it != sorted.end() && *it <= first[i] + max_difference; ++it) {
      const int j = order[it - sorted.begin()];
      candidates.emplace_back(std::abs(first[i] - second[j]), i, j);
    }
  }
  std::sort(candidates.begin(), candidates.end());

  std::vector<bool> first_used(first.size(), false), second_used(second.size(), false);
  std::vector<std::pair<int, int>> pairs;
  for (const auto& [difference, i, j] : candidates) {
    if (first_used[i] || second_used[j]) continue;
    first_used[i] = second_used[j] = true;
    pairs.emplace_back(i, j);
  }
  std::sort(pairs.begin(), pairs.end(), [&](const auto& a, const auto& b) {
    return std::make_pair(first[a.first], a.first) < std::make_pair(first[b.first], b.first);
  });
  return pairs;
}

std::optional<SE3> PoseAtTime(const std::vector<StampedPose>& samples, double time,
                              double max_difference) {
  const auto after =
      std::lower_bound(samples.begin(), samples.end(), time,
                       [](const StampedPose& sample, double t) { return sample.timestamp < t; });
  if (after != samples.end() && after->timestamp == time) return after->pose;
  const bool has_after = after != samples.end() && after->timestamp - time <= max_difference;
  const bool has_before =
      after != samples.begin() && time - std::prev(after)->timestamp <= max_difference;
  if (has_before && has_after) {
    const StampedPose& a = *std::prev(after);
    const StampedPose& b = *after;
    const double alpha = (time - a.timestamp) / (b.timestamp - a.timestamp);
    return SE3(a.pose.rotation().slerp(alpha, b.pose.rotation()),
               (1.0 - alpha) * a.pose.translation() + alpha * b.pose.translation());
  }
  if (has_before) return std::prev(after)->pose;
  if (has_after) return after->pose;
  return std::nullopt;
}

absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenTumDataset(const std::string& directory,
                                                            const DatasetOptions& options) {
  PLX_RETURN_IF_ERROR(CheckDatasetDirectory(directory));
  if (!(std::isfinite(options.max_time_difference) && options.max_time_difference >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_time_difference must be finite and >= 0, got ", options.max_time_difference));
  }
  PLX_ASSIGN_OR_RETURN(const CameraCalibration calibration,
                       LoadDatasetCalibration(directory, options.calibration));

  std::vector<FrameFiles> frames;
  if (FileExists(JoinPath(directory, kAssociationsFile))) {
    PLX_ASSIGN_OR_RETURN(frames, ReadAssociations(directory));
  } else if (FileExists(JoinPath(directory, kRgbListFile))) {
    PLX_ASSIGN_OR_RETURN(frames, AssociateFileLists(directory, options.max_time_difference));
  } else {
    return absl::NotFoundError(absl::StrCat(directory, ": a TUM sequence needs ", kAssociationsFile,
                                            " or ", kRgbListFile, " and ", kDepthListFile));
  }
  std::stable_sort(frames.begin(), frames.end(), [](const FrameFiles& a, const FrameFiles& b) {
    return a.timestamp < b.timestamp;
  });

  const std::string ground_truth_path = JoinPath(directory, kGroundTruthFile);
  if (FileExists(ground_truth_path)) {
    PLX_ASSIGN_OR_RETURN(const std::vector<StampedPose> samples,
                         ReadGroundTruth(ground_truth_path));
    for (FrameFiles& frame : frames) {
      frame.ground_truth = PoseAtTime(samples, frame.timestamp, options.max_time_difference);
    }
  }
  PLX_ASSIGN_OR_RETURN(
      std::unique_ptr<FileDataset> dataset,
      FileDataset::Create(DatasetNameFromDirectory(directory), calibration, std::move(frames)));
  return std::unique_ptr<RgbdDataset>(std::move(dataset));
}

}  // namespace plx

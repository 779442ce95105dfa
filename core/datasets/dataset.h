// RGB-D sequences on disk (TUM, Replica/NICE-SLAM, ScanNet export) or in memory (synthetic),
// behind one interface. Index files are parsed and checked when a dataset is opened; images
// are decoded lazily by LoadFrame so long sequences do not sit in memory.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"

namespace plx {

enum class DatasetFormat { kAuto, kTum, kReplica, kScanNet };

// Parses "auto", "tum", "replica", "scannet".
absl::StatusOr<DatasetFormat> ParseDatasetFormat(const std::string& name);
const char* DatasetFormatName(DatasetFormat format);

struct DatasetOptions {
  DatasetFormat format = DatasetFormat::kAuto;
  // When set, replaces the calibration from the dataset's intrinsics.txt (CLI flags).
  std::optional<CameraCalibration> calibration;
  // TUM: the largest |t_rgb - t_depth| accepted when associating by timestamp, and the largest
  // distance to the nearest ground-truth sample (seconds).
  double max_time_difference = 0.02;
};

class RgbdDataset {
 public:
  virtual ~RgbdDataset() = default;

  virtual std::string name() const = 0;
  // Calibration of the frames LoadFrame returns (already undistorted: distortion is zero).
  virtual const CameraCalibration& calibration() const = 0;
  virtual int size() const = 0;
  virtual double timestamp(int index) const = 0;
  // Ground-truth world_T_camera of frame `index`, when the dataset has one for it.
  virtual std::optional<SE3> ground_truth(int index) const = 0;
  // Decodes frame `index`: colour in [0,1], depth in metres, undistorted; errors name the file.
  virtual absl::StatusOr<RgbdFrame> LoadFrame(int index) const = 0;
};

// Opens the dataset in `directory`, detecting the layout when options.format is kAuto.
absl::StatusOr<std::unique_ptr<RgbdDataset>> OpenDataset(const std::string& directory,
                                                          const DatasetOptions& options = {});

// A dataset whose frames are already decoded (synthetic sequences, tests).
class InMemoryDataset final : public RgbdDataset {
 public:
  InMemoryDataset(std::string name, CameraCalibration calibration, std::vector<RgbdFrame> frames)
      : name_(std::move(name)), calibration_(calibration), frames_(std::move(frames)) {}

  std::string name() const override { return name_; }
  const CameraCalibration& calibration() const override { return calibration_; }
  int size() const override { return static_cast<int>(frames_.size()); }
  double timestamp(int index) const override { return frames_[index].timestamp; }
  std::optional<SE3> ground_truth(int index) const override {
    return frames_[index].ground_truth;
  }
  absl::StatusOr<RgbdFrame> LoadFrame(int index) const override { return frames_[index]; }
  const std::vector<RgbdFrame>& frames() const { return frames_; }

 private:
  std::string name_;
  CameraCalibration calibration_;
  std::vector<RgbdFrame> frames_;
};

// Writes `dataset` in the TUM layout of ../shared/data/README.md (rgb/, depth/ as 16-bit PNG
// with the calibration's depth scale, rgb.txt, depth.txt, associations.txt, groundtruth.txt,
// intrinsics.txt) so that OpenDataset reads it back. Creates `directory` if needed.
absl::Status WriteTumDataset(const RgbdDataset& dataset, const std::string& directory);

}  // namespace plx

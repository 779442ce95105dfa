// A TUM RGB-D sequence's index files as OpenTumDataset reads them (core/datasets/tum_dataset.h):
// rgb.txt and depth.txt (matched by timestamp), associations.txt, groundtruth.txt (interpolated
// at each frame's time).
//
// Input: the files' texts separated by NUL bytes, in the order of kFiles; an empty or missing
// part means the file is absent. The images listed must exist for a dataset to open, so the
// scratch folder holds a few empty image files the seeds list (fuzz/make_seeds.cc); they are
// never decoded (images are read lazily, and fuzz_image covers the decoders). The calibration
// is fixed (fuzz_text_files covers intrinsics.txt): a fuzzed size would make OpenTumDataset
// build undistortion maps of up to 16384^2 pixels on each run.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/datasets/tum_dataset.h"
#include "fuzz/fuzz_util.h"

namespace {

constexpr const char* kFiles[] = {"rgb.txt", "depth.txt", "associations.txt", "groundtruth.txt"};
// Listed by the seeds; created once, empty.
constexpr const char* kImages[] = {"rgb/1.000000.png", "rgb/2.000000.png", "depth/1.000000.png",
                                   "depth/2.000000.png"};

const std::string& SequenceDir() {
  static const std::string dir = [] {
    const std::string d = plx::fuzz::ScratchPath("seq");
    std::filesystem::create_directories(d + "/rgb");
    std::filesystem::create_directories(d + "/depth");
    for (const char* image : kImages) plx::fuzz::WriteFileOrDie(d + "/" + image, "");
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& dir = SequenceDir();
  const std::string input(reinterpret_cast<const char*>(data), size);
  size_t begin = 0;
  for (const char* name : kFiles) {
    const std::string path = dir + "/" + name;
    const size_t end = std::min(input.find('\0', begin), input.size());
    if (begin < input.size() && end > begin) {
      plx::fuzz::WriteFileOrDie(path, input.substr(begin, end - begin));
    } else {
      std::filesystem::remove(path);
    }
    begin = end < input.size() ? end + 1 : input.size();
  }

  plx::DatasetOptions options;
  options.format = plx::DatasetFormat::kTum;
  plx::CameraCalibration calibration;
  calibration.pinhole = {4.0, 4.0, 2.0, 1.5, 4, 3};
  calibration.depth_scale = 5000.0;
  options.calibration = calibration;
  // The second byte picks the association window, so the fuzzer also tries 0 and wide ones.
  options.max_time_difference = size > 1 ? (data[1] % 4) * 0.02 : 0.02;

  const absl::StatusOr<std::unique_ptr<plx::RgbdDataset>> dataset =
      plx::OpenTumDataset(dir, options);
  if (!dataset.ok()) return 0;
  const plx::RgbdDataset& d = **dataset;
  PLX_FUZZ_CHECK(d.size() > 0, "a dataset without frames opened");
  for (int i = 0; i < d.size(); ++i) {
    PLX_FUZZ_CHECK(std::isfinite(d.timestamp(i)), "non-finite frame timestamp");
    PLX_FUZZ_CHECK(i == 0 || d.timestamp(i - 1) <= d.timestamp(i), "frames out of time order");
    if (const std::optional<plx::SE3> pose = d.ground_truth(i)) {
      PLX_FUZZ_CHECK(pose->IsFinite(), "non-finite ground truth");
      PLX_FUZZ_CHECK(std::abs(pose->rotation().norm() - 1.0) < 1e-9,
                     "ground-truth rotation is not a unit quaternion");
    }
  }
  return 0;
}

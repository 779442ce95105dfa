// The hard start of a SLAM run: a copy of a TUM-layout dataset whose first frames have no depth
// at all (a depth camera's first frames, a covered lens), for the in-process and remote
// `plenox slam` tests alike.
#pragma once

#include <filesystem>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/clients/cli_runner.h"

namespace plx::testing {

// Copies `dataset` to `copy` and zeroes the depth images of its first `frames` associations.
// Empty on success, else what went wrong.
inline std::string CopyWithoutDepthAtStart(const std::string& dataset, const std::string& copy,
                                           int frames) {
  std::filesystem::copy(dataset, copy, std::filesystem::copy_options::recursive);
  const auto associations = ReadRows(copy + "/associations.txt");
  if (associations.size() <= static_cast<size_t>(frames)) return "too few frames";
  for (int i = 0; i < frames; ++i) {
    if (associations[i].size() != 4u) return "associations.txt: not 4 fields";
    const std::string path = copy + "/" + associations[i][3];
    cv::Mat depth = cv::imread(path, cv::IMREAD_UNCHANGED);
    if (depth.empty()) return "cannot read " + path;
    depth.setTo(0);
    if (!cv::imwrite(path, depth)) return "cannot write " + path;
  }
  return "";
}

}  // namespace plx::testing

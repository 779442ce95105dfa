// Small helpers for building dataset fixtures on disk, shared by the core/io, core/datasets and
// core/formats tests.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace plx::testing {

// Writes `text` to `path`, creating parent folders.
inline void WriteTextFile(const std::string& path, const std::string& text) {
  const std::filesystem::path p(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path());
  std::ofstream(path, std::ios::trunc) << text;
}

inline std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Writes an image with cv::imwrite, creating parent folders; returns imwrite's result.
inline bool WriteImage(const std::string& path, const cv::Mat& image) {
  const std::filesystem::path p(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path());
  return cv::imwrite(path, image);
}

// A colour image (OpenCV BGR order) whose pixel (u, v) is B = 7u + seed, G = 11v, R = 200 - seed:
// distinct per pixel and per frame, so tests can check channel order and which file was read.
inline cv::Mat PatternBgr(int width, int height, int seed) {
  cv::Mat image(height, width, CV_8UC3);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      image.at<cv::Vec3b>(v, u) =
          cv::Vec3b(static_cast<uint8_t>((7 * u + seed) % 256),
                    static_cast<uint8_t>((11 * v) % 256), static_cast<uint8_t>(200 - seed));
    }
  }
  return image;
}

// A 16-bit depth image filled with `raw`, with pixel (0, 0) set to 0 (no measurement).
inline cv::Mat ConstantDepth(int width, int height, uint16_t raw) {
  cv::Mat image(height, width, CV_16UC1, cv::Scalar(raw));
  image.at<uint16_t>(0, 0) = 0;
  return image;
}

}  // namespace plx::testing

// Image files <-> engine images. OpenCV stays behind this header: it decodes/encodes files,
// converts BGR to RGB, and undistorts. Every OpenCV exception becomes a Status naming the file.
//
// Colour files: 8-bit, 3 channels (1-channel grey is replicated, a 4th alpha channel dropped).
// Depth files: 16-bit, 1 channel; metres = value / depth_scale, 0 = no measurement.
#pragma once

#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/geometry/image.h"
#include "core/geometry/intrinsics.h"

namespace plx {

// Decoded but not yet converted: CV_8UC3 in RGB order, and CV_16UC1 raw depth. Loaders use
// these to resize and undistort before converting to float.
absl::StatusOr<cv::Mat> DecodeColorFile(const std::string& path);
absl::StatusOr<cv::Mat> DecodeDepthFile(const std::string& path);

// The same from encoded bytes in memory (PNG, JPEG); `what` names the source in errors
// (e.g. "frame.color"). Bytes that are not a PNG or JPEG (ReadImageHeader) are refused without
// reaching the codecs. These decode whatever size the header declares: callers that take
// images from clients check the header first (CheckFrameImageHeader, CheckFramePixels).
absl::StatusOr<cv::Mat> DecodeColorBuffer(const std::string& bytes, const std::string& what);
absl::StatusOr<cv::Mat> DecodeDepthBuffer(const std::string& bytes, const std::string& what);

// How many buffers this process has handed to the codecs (DecodeColorBuffer and
// DecodeDepthBuffer calls that got past the header): lets tests show a bad image was refused
// without being decoded.
int64_t ImageBuffersDecoded();

// Encoded bytes: colour as 8-bit RGB in the format of `extension` (".png", ".jpg"), depth as a
// 16-bit PNG of round(z * depth_scale).
absl::StatusOr<std::string> EncodeColorImage(const ColorImage& image, const std::string& extension);
absl::StatusOr<std::string> EncodeDepthImage(const DepthImage& image, double depth_scale);

// Raw wire layouts: width * height * 3 bytes of row-major 8-bit RGB, and width * height
// little-endian uint16 of round(z * depth_scale) (0 where there is no depth).
std::string ColorImageToRgb8Bytes(const ColorImage& image);
std::string DepthImageToU16Bytes(const DepthImage& image, double depth_scale);
// The inverse of DepthImageToU16Bytes: `bytes` must hold width * height * 2 bytes (callers check
// the count first). A 0 stays 0 (no measurement) whatever depth_scale is.
DepthImage DepthImageFromU16Bytes(const std::string& bytes, int width, int height,
                                  double depth_scale);

// CV_8UC3 RGB -> RGB in [0, 1]; CV_16UC1 -> metres (0 stays 0, as above).
ColorImage ColorImageFromMat(const cv::Mat& rgb8);
DepthImage DepthImageFromMat(const cv::Mat& depth16, double depth_scale);

// Whole-file conveniences.
absl::StatusOr<ColorImage> ReadColorImage(const std::string& path);
absl::StatusOr<DepthImage> ReadDepthImage(const std::string& path, double depth_scale);

// 8-bit colour (round(255 c), clamped); the format follows the extension (use .png).
absl::Status WriteColorImage(const std::string& path, const ColorImage& image);
// 16-bit PNG: round(z * depth_scale) clamped to 65535; 0 for z <= 0 or non-finite z.
absl::Status WriteDepthImage(const std::string& path, const DepthImage& image, double depth_scale);

// "WxH" for error messages.
std::string SizeString(int width, int height);

// Remaps images with Brown-Conrady distortion onto the pinhole camera of the same K. The maps
// are built once per calibration; applying them is thread-safe.
class Undistorter {
 public:
  // InvalidArgumentError for an invalid calibration or when OpenCV rejects it.
  static absl::StatusOr<Undistorter> Create(const CameraCalibration& calibration);

  // Bilinear; pixels that map outside the source become black.
  absl::StatusOr<cv::Mat> UndistortColor(const cv::Mat& rgb8) const;
  // Nearest neighbour, so no depth value is ever invented by blending across an edge; pixels
  // that map outside the source become 0 (invalid).
  absl::StatusOr<cv::Mat> UndistortDepth(const cv::Mat& depth16) const;

  int width() const { return map_x_.cols; }
  int height() const { return map_x_.rows; }

 private:
  Undistorter(cv::Mat map_x, cv::Mat map_y) : map_x_(std::move(map_x)), map_y_(std::move(map_y)) {}
  absl::StatusOr<cv::Mat> Remap(const cv::Mat& image, int interpolation) const;

  cv::Mat map_x_, map_y_;  // CV_32FC1: source pixel for each output pixel
};

}  // namespace plx

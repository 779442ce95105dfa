#include "core/io/image_io.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <system_error>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/io/image_header.h"
#include "core/io/png_decode.h"

namespace plx {
namespace {

const char* BitDepthName(int cv_depth) {
  switch (cv_depth) {
    case CV_8U:
      return "8-bit unsigned";
    case CV_8S:
      return "8-bit signed";
    case CV_16U:
      return "16-bit unsigned";
    case CV_16S:
      return "16-bit signed";
    case CV_32S:
      return "32-bit integer";
    case CV_32F:
      return "32-bit float";
    case CV_64F:
      return "64-bit float";
    default:
      return "unknown bit depth";
  }
}

std::string Describe(const cv::Mat& image) {
  return absl::StrCat(SizeString(image.cols, image.rows), ", ", BitDepthName(image.depth()), ", ",
                      image.channels(), image.channels() == 1 ? " channel" : " channels");
}

// imread returns an empty Mat for most failures but may also throw; both become a Status.
absl::StatusOr<cv::Mat> ReadRaw(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrCat(path, ": image file not found"));
  }
  cv::Mat image;
  try {
    image = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": cannot decode image: ", e.what()));
  }
  if (image.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot read or decode image (corrupt or not an image file)"));
  }
  return image;
}

absl::Status WriteMat(const std::string& path, const cv::Mat& image) {
  try {
    if (!cv::imwrite(path, image)) {
      return absl::PermissionDeniedError(absl::StrCat(path, ": cannot write image"));
    }
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": cannot write image: ", e.what()));
  }
  return absl::OkStatus();
}

absl::Status CheckImageShape(const std::string& path, int width, int height, int channels,
                             size_t data_size, int expected_channels) {
  if (width <= 0 || height <= 0 || channels != expected_channels ||
      data_size != static_cast<size_t>(width) * height * channels) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": cannot write a ", SizeString(width, height), " image with ", channels,
        " channels and ", data_size, " values (need ", expected_channels, " channels)"));
  }
  return absl::OkStatus();
}

// 8-bit grey, BGR or BGRA as decoded by OpenCV -> RGB8; `what` names the source in errors.
absl::StatusOr<cv::Mat> ToRgb8(const cv::Mat& image, const std::string& path) {
  if (image.depth() != CV_8U) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": colour images must be 8-bit with 1, 3 or 4 channels, got ", Describe(image)));
  }
  int conversion = -1;
  switch (image.channels()) {
    case 1:
      conversion = cv::COLOR_GRAY2RGB;
      break;
    case 3:
      conversion = cv::COLOR_BGR2RGB;
      break;
    case 4:
      conversion = cv::COLOR_BGRA2RGB;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          path, ": colour images must be 8-bit with 1, 3 or 4 channels, got ", Describe(image)));
  }
  cv::Mat rgb;
  try {
    cv::cvtColor(image, rgb, conversion);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": colour conversion failed: ", e.what()));
  }
  return rgb;
}

absl::StatusOr<cv::Mat> CheckDepth16(const cv::Mat& image, const std::string& path) {
  if (image.type() != CV_16UC1) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": depth images must be 16-bit unsigned with 1 channel, got ", Describe(image)));
  }
  return image;
}

std::atomic<int64_t> buffers_decoded{0};

absl::StatusOr<cv::Mat> DecodeBuffer(const std::string& bytes, const std::string& what) {
  // Bytes from the network reach only OpenCV's PNG and JPEG codecs, whose headers callers can
  // check first (image_header.h); imdecode alone would try every format it was built with.
  PLX_ASSIGN_OR_RETURN(const ImageHeader header, ReadImageHeader(bytes, what));
  buffers_decoded.fetch_add(1, std::memory_order_relaxed);
  // PNGs go to libpng directly, whose errors then come back here instead of to stderr.
  if (header.format == ImageFormat::kPng) return DecodePng(bytes, what);
  cv::Mat image;
  try {
    const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1,
                         const_cast<char*>(bytes.data()));
    image = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": cannot decode image: ", e.what()));
  }
  if (image.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": cannot decode image (corrupt JPEG)"));
  }
  return image;
}

uint8_t ToByte(float value) {
  return static_cast<uint8_t>(
      std::lround(std::clamp(std::isfinite(value) ? value : 0.0f, 0.0f, 1.0f) * 255.0f));
}

uint16_t ToDepthUnits(float z, double depth_scale) {
  return (std::isfinite(z) && z > 0)
             ? static_cast<uint16_t>(std::min(std::round(z * depth_scale), 65535.0))
             : 0;
}

// Depth units -> metres. 0 is "no measurement" at any scale: with a depth_scale so small that
// its inverse overflows (a client may send 1e-310), 0 * inf would be NaN, and NaN passes the
// "z <= 0 || z > max_depth" tests that drop invalid samples (depth fusion has one). Other
// values may become +inf, which every consumer drops as beyond its max_depth.
float DepthFromUnits(uint16_t units, double inv_scale) {
  return units == 0 ? 0.0f : static_cast<float>(units * inv_scale);
}

cv::Mat ColorImageToBgr8(const ColorImage& image) {
  cv::Mat bgr(image.height, image.width, CV_8UC3);
  for (int v = 0; v < image.height; ++v) {
    uint8_t* dst = bgr.ptr<uint8_t>(v);
    for (int u = 0; u < image.width; ++u) {
      const float* rgb = image.pixel(u, v);
      for (int c = 0; c < 3; ++c) dst[3 * u + (2 - c)] = ToByte(rgb[c]);
    }
  }
  return bgr;
}

cv::Mat DepthImageToU16(const DepthImage& image, double depth_scale) {
  cv::Mat raw(image.height, image.width, CV_16UC1);
  for (int v = 0; v < image.height; ++v) {
    uint16_t* dst = raw.ptr<uint16_t>(v);
    const float* src = image.pixel(0, v);
    for (int u = 0; u < image.width; ++u) dst[u] = ToDepthUnits(src[u], depth_scale);
  }
  return raw;
}

absl::StatusOr<std::string> EncodeMat(const cv::Mat& image, const std::string& extension) {
  std::vector<uint8_t> bytes;
  try {
    if (!cv::imencode(extension, image, bytes)) {
      return absl::InternalError(absl::StrCat("cannot encode image as ", extension));
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("cannot encode image as ", extension, ": ", e.what()));
  }
  return std::string(bytes.begin(), bytes.end());
}

}  // namespace

std::string SizeString(int width, int height) { return absl::StrCat(width, "x", height); }

int64_t ImageBuffersDecoded() { return buffers_decoded.load(std::memory_order_relaxed); }

absl::StatusOr<cv::Mat> DecodeColorFile(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(cv::Mat image, ReadRaw(path));
  return ToRgb8(image, path);
}

absl::StatusOr<cv::Mat> DecodeDepthFile(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(cv::Mat image, ReadRaw(path));
  return CheckDepth16(image, path);
}

absl::StatusOr<cv::Mat> DecodeColorBuffer(const std::string& bytes, const std::string& what) {
  PLX_ASSIGN_OR_RETURN(cv::Mat image, DecodeBuffer(bytes, what));
  return ToRgb8(image, what);
}

absl::StatusOr<cv::Mat> DecodeDepthBuffer(const std::string& bytes, const std::string& what) {
  PLX_ASSIGN_OR_RETURN(cv::Mat image, DecodeBuffer(bytes, what));
  return CheckDepth16(image, what);
}

absl::StatusOr<std::string> EncodeColorImage(const ColorImage& image,
                                             const std::string& extension) {
  PLX_RETURN_IF_ERROR(CheckImageShape("colour image", image.width, image.height, image.channels,
                                      image.data.size(), 3));
  return EncodeMat(ColorImageToBgr8(image), extension);
}

absl::StatusOr<std::string> EncodeDepthImage(const DepthImage& image, double depth_scale) {
  PLX_RETURN_IF_ERROR(CheckImageShape("depth image", image.width, image.height, image.channels,
                                      image.data.size(), 1));
  return EncodeMat(DepthImageToU16(image, depth_scale), ".png");
}

std::string ColorImageToRgb8Bytes(const ColorImage& image) {
  std::string bytes(image.data.size(), '\0');
  for (size_t i = 0; i < image.data.size(); ++i) {
    bytes[i] = static_cast<char>(ToByte(image.data[i]));
  }
  return bytes;
}

std::string DepthImageToU16Bytes(const DepthImage& image, double depth_scale) {
  std::string bytes(2 * image.data.size(), '\0');
  for (size_t i = 0; i < image.data.size(); ++i) {
    const uint16_t units = ToDepthUnits(image.data[i], depth_scale);
    bytes[2 * i] = static_cast<char>(units & 0xff);
    bytes[2 * i + 1] = static_cast<char>(units >> 8);
  }
  return bytes;
}

DepthImage DepthImageFromU16Bytes(const std::string& bytes, int width, int height,
                                  double depth_scale) {
  DepthImage image(width, height, 1);
  const auto* src = reinterpret_cast<const uint8_t*>(bytes.data());
  const double inv_scale = 1.0 / depth_scale;
  for (size_t i = 0; i < image.data.size(); ++i) {
    image.data[i] = DepthFromUnits(static_cast<uint16_t>(src[2 * i] | (src[2 * i + 1] << 8)),
                                   inv_scale);
  }
  return image;
}

ColorImage ColorImageFromMat(const cv::Mat& rgb8) {
  ColorImage image(rgb8.cols, rgb8.rows, 3);
  constexpr float kInv255 = 1.0f / 255.0f;
  for (int v = 0; v < rgb8.rows; ++v) {
    const uint8_t* src = rgb8.ptr<uint8_t>(v);
    float* dst = image.pixel(0, v);
    for (int i = 0; i < rgb8.cols * 3; ++i) dst[i] = src[i] * kInv255;
  }
  return image;
}

DepthImage DepthImageFromMat(const cv::Mat& depth16, double depth_scale) {
  DepthImage image(depth16.cols, depth16.rows, 1);
  const double inv_scale = 1.0 / depth_scale;
  for (int v = 0; v < depth16.rows; ++v) {
    const uint16_t* src = depth16.ptr<uint16_t>(v);
    float* dst = image.pixel(0, v);
    for (int u = 0; u < depth16.cols; ++u) dst[u] = DepthFromUnits(src[u], inv_scale);
  }
  return image;
}

absl::StatusOr<ColorImage> ReadColorImage(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const cv::Mat rgb, DecodeColorFile(path));
  return ColorImageFromMat(rgb);
}

absl::StatusOr<DepthImage> ReadDepthImage(const std::string& path, double depth_scale) {
  if (!(std::isfinite(depth_scale) && depth_scale > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": depth scale must be positive, got ", depth_scale));
  }
  PLX_ASSIGN_OR_RETURN(const cv::Mat depth, DecodeDepthFile(path));
  return DepthImageFromMat(depth, depth_scale);
}

absl::Status WriteColorImage(const std::string& path, const ColorImage& image) {
  PLX_RETURN_IF_ERROR(
      CheckImageShape(path, image.width, image.height, image.channels, image.data.size(), 3));
  return WriteMat(path, ColorImageToBgr8(image));  // OpenCV's BGR order
}

absl::Status WriteDepthImage(const std::string& path, const DepthImage& image, double depth_scale) {
  PLX_RETURN_IF_ERROR(
      CheckImageShape(path, image.width, image.height, image.channels, image.data.size(), 1));
  if (!(std::isfinite(depth_scale) && depth_scale > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": depth scale must be positive, got ", depth_scale));
  }
  return WriteMat(path, DepthImageToU16(image, depth_scale));
}

absl::StatusOr<Undistorter> Undistorter::Create(const CameraCalibration& calibration) {
  if (absl::Status status = ValidateCalibration(calibration); !status.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("undistortion: ", status.message()));
  }
  const PinholeIntrinsics& k = calibration.pinhole;
  const Distortion& d = calibration.distortion;
  // The engine puts pixel centres at (u + 0.5, v + 0.5) while OpenCV puts them at integer
  // (u, v); shifting the principal point keeps the remap consistent with how rays are cast.
  const cv::Matx33d camera(k.fx, 0, k.cx - 0.5, 0, k.fy, k.cy - 0.5, 0, 0, 1);
  const cv::Matx<double, 1, 5> coefficients(d.k1, d.k2, d.p1, d.p2, d.k3);
  cv::Mat map_x, map_y;
  try {
    cv::initUndistortRectifyMap(camera, coefficients, cv::noArray(), camera,
                                cv::Size(k.width, k.height), CV_32FC1, map_x, map_y);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("undistortion maps failed: ", e.what()));
  }
  return Undistorter(std::move(map_x), std::move(map_y));
}

absl::StatusOr<cv::Mat> Undistorter::Remap(const cv::Mat& image, int interpolation) const {
  if (image.cols != width() || image.rows != height()) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot undistort a ", SizeString(image.cols, image.rows),
                     " image with a calibration for ", SizeString(width(), height())));
  }
  cv::Mat out;
  try {
    cv::remap(image, out, map_x_, map_y_, interpolation, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("undistortion failed: ", e.what()));
  }
  return out;
}

absl::StatusOr<cv::Mat> Undistorter::UndistortColor(const cv::Mat& rgb8) const {
  return Remap(rgb8, cv::INTER_LINEAR);
}

absl::StatusOr<cv::Mat> Undistorter::UndistortDepth(const cv::Mat& depth16) const {
  return Remap(depth16, cv::INTER_NEAREST);
}

}  // namespace plx

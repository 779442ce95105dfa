#include "proto/frame_codec.h"

#include <cmath>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/io/image_header.h"
#include "core/io/image_io.h"

namespace plx {
namespace {

absl::Status Invalid(const std::string& field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", what));
}

// The cheap half of the image checks (on the gRPC thread): raw byte counts, and for encoded
// images the header against the intrinsics, so nothing is decoded that cannot be used.
absl::Status CheckColor(const pb::Frame& frame, const std::string& field, int width, int height) {
  const std::string name = field + ".color";
  switch (frame.color_encoding()) {
    case pb::COLOR_ENCODING_RAW_RGB8: {
      const size_t expected = static_cast<size_t>(width) * height * 3;
      if (frame.color().size() != expected) {
        return Invalid(name, absl::StrCat("raw RGB8 needs ", expected, " bytes for ", width, "x",
                                          height, ", got ", frame.color().size()));
      }
      return absl::OkStatus();
    }
    case pb::COLOR_ENCODING_PNG:
    case pb::COLOR_ENCODING_JPEG: {
      // Either label takes either format: the header says which one the bytes are.
      PLX_ASSIGN_OR_RETURN(const ImageHeader header, ReadImageHeader(frame.color(), name));
      return CheckFrameImageHeader(header, FrameImageRole::kColor, width, height, name);
    }
    default:
      return Invalid(field + ".color_encoding", "must be PNG, JPEG or RAW_RGB8");
  }
}

absl::Status CheckDepth(const pb::Frame& frame, const std::string& field, int width, int height) {
  const std::string name = field + ".depth";
  switch (frame.depth_encoding()) {
    case pb::DEPTH_ENCODING_RAW_U16: {
      const size_t pixels = static_cast<size_t>(width) * height;
      if (frame.depth().size() != 2 * pixels) {
        return Invalid(name, absl::StrCat("raw uint16 depth needs ", 2 * pixels, " bytes for ",
                                          width, "x", height, ", got ", frame.depth().size()));
      }
      return absl::OkStatus();
    }
    case pb::DEPTH_ENCODING_PNG16: {
      PLX_ASSIGN_OR_RETURN(const ImageHeader header, ReadImageHeader(frame.depth(), name));
      return CheckFrameImageHeader(header, FrameImageRole::kDepth, width, height, name);
    }
    default:
      return Invalid(field + ".depth_encoding", "must be PNG16 or RAW_U16");
  }
}

// The decoder's size is checked again: for any image the codec accepts it agrees with the
// header, and the check costs nothing.
absl::Status CheckDecodedSize(const cv::Mat& image, const std::string& name, int width,
                              int height) {
  if (image.cols != width || image.rows != height) {
    return Invalid(name, absl::StrCat("image is ", image.cols, "x", image.rows,
                                      ", the intrinsics say ", width, "x", height));
  }
  return absl::OkStatus();
}

// The expensive half (on a worker), for a frame CheckColor/CheckDepth passed.
absl::StatusOr<ColorImage> DecodeColor(const pb::Frame& frame, const std::string& field, int width,
                                       int height) {
  const std::string name = field + ".color";
  if (frame.color_encoding() == pb::COLOR_ENCODING_RAW_RGB8) {
    ColorImage image(width, height, 3);
    const uint8_t* src = reinterpret_cast<const uint8_t*>(frame.color().data());
    for (size_t i = 0; i < image.data.size(); ++i) image.data[i] = src[i] * (1.0f / 255.0f);
    return image;
  }
  PLX_ASSIGN_OR_RETURN(cv::Mat rgb, DecodeColorBuffer(frame.color(), name));
  PLX_RETURN_IF_ERROR(CheckDecodedSize(rgb, name, width, height));
  return ColorImageFromMat(rgb);
}

absl::StatusOr<DepthImage> DecodeDepth(const pb::Frame& frame, const std::string& field, int width,
                                       int height, double depth_scale) {
  const std::string name = field + ".depth";
  if (frame.depth_encoding() == pb::DEPTH_ENCODING_RAW_U16) {
    return DepthImageFromU16Bytes(frame.depth(), width, height, depth_scale);  // size checked
  }
  PLX_ASSIGN_OR_RETURN(cv::Mat raw, DecodeDepthBuffer(frame.depth(), name));
  PLX_RETURN_IF_ERROR(CheckDecodedSize(raw, name, width, height));
  return DepthImageFromMat(raw, depth_scale);
}

}  // namespace

void IntrinsicsToProto(const PinholeIntrinsics& k, double depth_scale, pb::Intrinsics* out) {
  out->set_fx(k.fx);
  out->set_fy(k.fy);
  out->set_cx(k.cx);
  out->set_cy(k.cy);
  out->set_width(static_cast<uint32_t>(k.width));
  out->set_height(static_cast<uint32_t>(k.height));
  out->set_depth_scale(depth_scale);
}

absl::StatusOr<CameraCalibration> IntrinsicsFromProto(const pb::Intrinsics& k,
                                                      const std::string& field,
                                                      bool require_depth_scale) {
  CameraCalibration c;
  c.pinhole = PinholeIntrinsics{k.fx(), k.fy(), k.cx(), k.cy(), static_cast<int>(k.width()),
                                static_cast<int>(k.height())};
  // Without one (Render: no depth comes in), core's default keeps the calibration valid.
  c.depth_scale = require_depth_scale ? k.depth_scale() : CameraCalibration().depth_scale;
  // Checked on the wire's uint32 before the cast to int could wrap.
  const uint32_t max_side = static_cast<uint32_t>(kMaxImageSide);
  if (k.width() > max_side || k.height() > max_side) {
    return Invalid(field, absl::StrCat("image size ", k.width(), "x", k.height(),
                                       " is larger than ", kMaxImageSide, "x", kMaxImageSide));
  }
  if (absl::Status s = ValidateCalibration(c); !s.ok()) {
    return Invalid(field, std::string(s.message()));
  }
  return c;
}

absl::StatusOr<CheckedFrame> CheckFrame(pb::Frame frame, const std::string& field,
                                        bool require_pose, int64_t max_pixels) {
  if (!frame.has_intrinsics()) return Invalid(field + ".intrinsics", "missing");
  CheckedFrame out;
  PLX_ASSIGN_OR_RETURN(out.calibration,
                       IntrinsicsFromProto(frame.intrinsics(), field + ".intrinsics", true));
  const int w = out.calibration.pinhole.width, h = out.calibration.pinhole.height;
  if (absl::Status s = CheckFramePixels(w, h, max_pixels, field + ".intrinsics"); !s.ok()) {
    return absl::ResourceExhaustedError(absl::StrCat(s.message(), " (--max-frame-pixels)"));
  }
  if (!std::isfinite(frame.timestamp())) return Invalid(field + ".timestamp", "not finite");
  PLX_RETURN_IF_ERROR(CheckColor(frame, field, w, h));
  PLX_RETURN_IF_ERROR(CheckDepth(frame, field, w, h));
  if (frame.has_pose()) {
    PLX_ASSIGN_OR_RETURN(out.client_pose, PoseFromProto(frame.pose(), field + ".pose"));
  } else if (require_pose) {
    return Invalid(field + ".pose", "required (mapping needs every keyframe's pose)");
  }
  out.frame = std::move(frame);
  out.field = field;
  return out;
}

absl::StatusOr<pb::Frame> FrameToProto(const RgbdFrame& frame, const CameraCalibration& calibration,
                                       const std::optional<SE3>& pose,
                                       const FrameEncoding& encoding,
                                       const std::string& camera_id) {
  pb::Frame out;
  out.set_camera_id(camera_id);
  out.set_timestamp(frame.timestamp);
  IntrinsicsToProto(calibration.pinhole, calibration.depth_scale, out.mutable_intrinsics());
  switch (encoding.color) {
    case pb::COLOR_ENCODING_RAW_RGB8: out.set_color(ColorImageToRgb8Bytes(frame.color)); break;
    case pb::COLOR_ENCODING_PNG:
    case pb::COLOR_ENCODING_JPEG: {
      const char* extension = encoding.color == pb::COLOR_ENCODING_PNG ? ".png" : ".jpg";
      PLX_ASSIGN_OR_RETURN(*out.mutable_color(), EncodeColorImage(frame.color, extension));
      break;
    }
    default: return Invalid("color_encoding", "must be PNG, JPEG or RAW_RGB8");
  }
  out.set_color_encoding(encoding.color);
  switch (encoding.depth) {
    case pb::DEPTH_ENCODING_RAW_U16:
      out.set_depth(DepthImageToU16Bytes(frame.depth, calibration.depth_scale));
      break;
    case pb::DEPTH_ENCODING_PNG16: {
      PLX_ASSIGN_OR_RETURN(*out.mutable_depth(),
                           EncodeDepthImage(frame.depth, calibration.depth_scale));
      break;
    }
    default: return Invalid("depth_encoding", "must be PNG16 or RAW_U16");
  }
  out.set_depth_encoding(encoding.depth);
  if (pose) PoseToProto(*pose, out.mutable_pose());
  return out;
}

absl::StatusOr<DecodedFrame> DecodeCheckedFrame(CheckedFrame checked) {
  // Decoded images are UnifiedVectors: out of memory throws std::bad_alloc, which must fail this
  // request, not unwind through the worker.
  return CatchAllocationFailure(
      absl::StrCat("decoding ", checked.field), [&]() -> absl::StatusOr<DecodedFrame> {
        const pb::Frame& f = checked.frame;
        const int w = checked.calibration.pinhole.width, h = checked.calibration.pinhole.height;
        DecodedFrame out;
        out.frame.timestamp = f.timestamp();
        PLX_ASSIGN_OR_RETURN(out.frame.color, DecodeColor(f, checked.field, w, h));
        PLX_ASSIGN_OR_RETURN(out.frame.depth, DecodeDepth(f, checked.field, w, h,
                                                          checked.calibration.depth_scale));
        out.calibration = checked.calibration;
        out.camera_id = f.camera_id();
        out.client_pose = checked.client_pose;
        return out;
      });
}

}  // namespace plx

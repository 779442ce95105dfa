#include "server/proto_convert.h"

#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/io/image_io.h"

namespace plx::server {
namespace {

absl::Status Invalid(const std::string& field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", what));
}

absl::StatusOr<ColorImage> DecodeColor(const pb::Frame& frame, const std::string& field, int width,
                                       int height) {
  const std::string name = field + ".color";
  switch (frame.color_encoding()) {
    case pb::COLOR_ENCODING_RAW_RGB8: {
      const size_t expected = static_cast<size_t>(width) * height * 3;
      if (frame.color().size() != expected) {
        return Invalid(name, absl::StrCat("raw RGB8 needs ", expected, " bytes for ", width, "x",
                                          height, ", got ", frame.color().size()));
      }
      ColorImage image(width, height, 3);
      const uint8_t* src = reinterpret_cast<const uint8_t*>(frame.color().data());
      for (size_t i = 0; i < expected; ++i) image.data[i] = src[i] * (1.0f / 255.0f);
      return image;
    }
    case pb::COLOR_ENCODING_PNG:
    case pb::COLOR_ENCODING_JPEG: {
      PLX_ASSIGN_OR_RETURN(cv::Mat rgb, DecodeColorBuffer(frame.color(), name));
      if (rgb.cols != width || rgb.rows != height) {
        return Invalid(name, absl::StrCat("image is ", rgb.cols, "x", rgb.rows,
                                          ", the intrinsics say ", width, "x", height));
      }
      return ColorImageFromMat(rgb);
    }
    default:
      return Invalid(field + ".color_encoding", "must be PNG, JPEG or RAW_RGB8");
  }
}

absl::StatusOr<DepthImage> DecodeDepth(const pb::Frame& frame, const std::string& field, int width,
                                       int height, double depth_scale) {
  const std::string name = field + ".depth";
  switch (frame.depth_encoding()) {
    case pb::DEPTH_ENCODING_RAW_U16: {
      const size_t pixels = static_cast<size_t>(width) * height;
      if (frame.depth().size() != 2 * pixels) {
        return Invalid(name, absl::StrCat("raw uint16 depth needs ", 2 * pixels, " bytes for ",
                                          width, "x", height, ", got ", frame.depth().size()));
      }
      DepthImage image(width, height, 1);
      const uint8_t* src = reinterpret_cast<const uint8_t*>(frame.depth().data());
      const double inv = 1.0 / depth_scale;
      for (size_t i = 0; i < pixels; ++i) {
        const uint16_t raw = static_cast<uint16_t>(src[2 * i] | (src[2 * i + 1] << 8));
        image.data[i] = static_cast<float>(raw * inv);
      }
      return image;
    }
    case pb::DEPTH_ENCODING_PNG16: {
      PLX_ASSIGN_OR_RETURN(cv::Mat raw, DecodeDepthBuffer(frame.depth(), name));
      if (raw.cols != width || raw.rows != height) {
        return Invalid(name, absl::StrCat("image is ", raw.cols, "x", raw.rows,
                                          ", the intrinsics say ", width, "x", height));
      }
      return DepthImageFromMat(raw, depth_scale);
    }
    default:
      return Invalid(field + ".depth_encoding", "must be PNG16 or RAW_U16");
  }
}

}  // namespace

absl::StatusOr<CameraCalibration> IntrinsicsFromProto(const pb::Intrinsics& k,
                                                      const std::string& field,
                                                      bool require_depth_scale) {
  CameraCalibration c;
  c.pinhole = PinholeIntrinsics{k.fx(), k.fy(), k.cx(), k.cy(), static_cast<int>(k.width()),
                                static_cast<int>(k.height())};
  c.depth_scale = require_depth_scale ? k.depth_scale() : 1000.0;
  if (k.width() > 16384 || k.height() > 16384) {
    return Invalid(field, absl::StrCat("image size ", k.width(), "x", k.height(),
                                       " is larger than 16384x16384"));
  }
  if (absl::Status s = ValidateCalibration(c); !s.ok()) return Invalid(field, std::string(s.message()));
  return c;
}

namespace {

absl::StatusOr<DecodedFrame> DecodeFrame(const pb::Frame& frame, const std::string& field,
                                         bool require_pose) {
  if (!frame.has_intrinsics()) return Invalid(field + ".intrinsics", "missing");
  DecodedFrame out;
  PLX_ASSIGN_OR_RETURN(out.calibration,
                       IntrinsicsFromProto(frame.intrinsics(), field + ".intrinsics", true));
  if (!std::isfinite(frame.timestamp())) return Invalid(field + ".timestamp", "not finite");
  const int w = out.calibration.pinhole.width, h = out.calibration.pinhole.height;
  out.frame.timestamp = frame.timestamp();
  PLX_ASSIGN_OR_RETURN(out.frame.color, DecodeColor(frame, field, w, h));
  PLX_ASSIGN_OR_RETURN(out.frame.depth,
                       DecodeDepth(frame, field, w, h, out.calibration.depth_scale));
  if (frame.has_pose()) {
    PLX_ASSIGN_OR_RETURN(out.client_pose, PoseFromProto(frame.pose(), field + ".pose"));
  } else if (require_pose) {
    return Invalid(field + ".pose", "required (mapping needs every keyframe's pose)");
  }
  out.camera_id = frame.camera_id();
  return out;
}

}  // namespace

absl::StatusOr<DecodedFrame> FrameFromProto(const pb::Frame& frame, const std::string& field,
                                            bool require_pose) {
  // Decoded images are UnifiedVectors: out of memory throws std::bad_alloc, which must fail this
  // request, not unwind through gRPC's callback thread.
  return CatchAllocationFailure(absl::StrCat("decoding ", field),
                                [&] { return DecodeFrame(frame, field, require_pose); });
}

absl::Status RenderedViewToProto(const RenderedView& view, pb::ColorEncoding color_encoding,
                                 pb::DepthEncoding depth_encoding, pb::RenderResponse* out) {
  out->set_width(view.color.width);
  out->set_height(view.color.height);
  switch (color_encoding) {
    case pb::COLOR_ENCODING_UNSPECIFIED:
    case pb::COLOR_ENCODING_PNG: {
      PLX_ASSIGN_OR_RETURN(*out->mutable_color(), EncodeColorImage(view.color, ".png"));
      out->set_color_encoding(pb::COLOR_ENCODING_PNG);
      break;
    }
    case pb::COLOR_ENCODING_JPEG: {
      PLX_ASSIGN_OR_RETURN(*out->mutable_color(), EncodeColorImage(view.color, ".jpg"));
      out->set_color_encoding(pb::COLOR_ENCODING_JPEG);
      break;
    }
    case pb::COLOR_ENCODING_RAW_RGB8: {
      *out->mutable_color() = ColorImageToRgb8Bytes(view.color);
      out->set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
      break;
    }
    default:
      return Invalid("color_encoding", "unknown encoding");
  }
  switch (depth_encoding) {
    case pb::DEPTH_ENCODING_UNSPECIFIED:
    case pb::DEPTH_ENCODING_PNG16: {
      PLX_ASSIGN_OR_RETURN(*out->mutable_depth(), EncodeDepthImage(view.z_depth, 1000.0));
      out->set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
      break;
    }
    case pb::DEPTH_ENCODING_RAW_U16: {
      *out->mutable_depth() = DepthImageToU16Bytes(view.z_depth, 1000.0);
      out->set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
      break;
    }
    default:
      return Invalid("depth_encoding", "unknown encoding");
  }
  return absl::OkStatus();
}

absl::Status CheckMapName(const std::string& name, const std::string& field) {
  if (name.empty() || name.size() > 64 || name[0] == '.') {
    return Invalid(field, absl::StrCat("map names are 1-64 characters of [A-Za-z0-9_.-] not "
                                       "starting with '.', got \"", name, "\""));
  }
  for (char c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-')) {
      return Invalid(field, absl::StrCat("map names use [A-Za-z0-9_.-] only, got \"", name, "\""));
    }
  }
  return absl::OkStatus();
}

}  // namespace plx::server

#include "proto/render_codec.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/io/image_io.h"

namespace plx {
namespace {

absl::Status Invalid(const std::string& field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", what));
}

// A RenderResponse's depth is in millimetres (plenoxd.proto): 1000 units per metre.
constexpr double kRenderDepthScale = 1000.0;

}  // namespace

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
      PLX_ASSIGN_OR_RETURN(*out->mutable_depth(),
                           EncodeDepthImage(view.z_depth, kRenderDepthScale));
      out->set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
      break;
    }
    case pb::DEPTH_ENCODING_RAW_U16: {
      *out->mutable_depth() = DepthImageToU16Bytes(view.z_depth, kRenderDepthScale);
      out->set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
      break;
    }
    default:
      return Invalid("depth_encoding", "unknown encoding");
  }
  return absl::OkStatus();
}

}  // namespace plx

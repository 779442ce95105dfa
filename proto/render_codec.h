// A rendered view -> plenoxd.v1 RenderResponse (the images encoded as the request asked). The
// response's size bound is proto/render_size.h.
#pragma once

#include "absl/status/status.h"
#include "core/render/render_view.h"
#include "proto/wire.h"

namespace plx {

// Encodes a rendered view for a RenderResponse.
absl::Status RenderedViewToProto(const RenderedView& view, pb::ColorEncoding color_encoding,
                                 pb::DepthEncoding depth_encoding, pb::RenderResponse* out);

}  // namespace plx

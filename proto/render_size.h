// How large a RenderResponse can get, from the request alone: the one rule the daemon (before
// it renders) and the plenox CLI (before it asks) use to refuse a Render whose answer would not
// fit in a gRPC message, instead of rendering for seconds and then failing on the send.
#pragma once

#include <cstdint>

#include "absl/status/status.h"
#include "plenoxd/v1/plenoxd.pb.h"

namespace plx {

// The most bytes a RenderResponse of a width x height view in these encodings can take: exact
// for the raw encodings, the codec's worst case (an incompressible image) for PNG and JPEG, plus
// the message's own framing. Unspecified encodings are the defaults (PNG, PNG16); unknown ones
// count as raw (the daemon refuses them after rendering anyway).
int64_t RenderResponseBytesBound(int64_t width, int64_t height,
                                 ::plenoxd::v1::ColorEncoding color_encoding,
                                 ::plenoxd::v1::DepthEncoding depth_encoding);

// OK when the response to `request` (its intrinsics' size and its encodings) fits in
// `max_message_bytes`; otherwise RESOURCE_EXHAUSTED "a W x H render with PNG colour and PNG16
// depth may take up to N bytes, over the largest message of M bytes".
absl::Status CheckRenderResponseSize(const ::plenoxd::v1::RenderRequest& request,
                                     int64_t max_message_bytes);

}  // namespace plx

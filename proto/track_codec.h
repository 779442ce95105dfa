// plenoxd.v1 Track messages <-> core/tracking: the tracker's options from a TrackOptions (the
// Track stream's own, and the `tracking` part of Slam's) and the tracking state of a reply.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "core/tracking/tracker.h"
#include "proto/wire.h"

namespace plx {

// TrackerOptionsForMode(mode) with the message's non-zero rays and iterations on top (0 means
// core's default). INVALID_ARGUMENT when the mode is not one the proto declares ("<field>.mode:
// unknown mode 7 ...": proto3 enums are open, an unknown number must not become the default) or
// when Tracker::ValidateOptions refuses the result ("<field>: ..."). `field` names the message:
// "options" for Track, "options.tracking" inside Slam.
absl::StatusOr<TrackerOptions> TrackerOptionsFromProto(const pb::TrackOptions& options,
                                                       const std::string& field);

pb::TrackingState TrackingStateToProto(TrackingState state);

}  // namespace plx

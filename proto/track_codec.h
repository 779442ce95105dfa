// plenoxd.v1 Track messages <-> core/tracking: the tracker's options both ways (a TrackOptions
// is the Track stream's own and the `tracking` part of Slam's; the daemon reads it, the CLI
// writes it), the tracking state, and the PoseEstimate a Track stream answers a frame with.
#pragma once

#include <cstdint>
#include <optional>
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

// Which of a TrackerOptions' numbers a client chose: only those go on the wire, the others stay
// 0 (the daemon's defaults for the mode), so that nobody's unchosen value overrides them.
struct TrackOptionsFields {
  bool rays = false;
  bool iterations = false;
  bool pixels = false;
};

// The inverse of TrackerOptionsFromProto: the mode always, rays, iterations and pixels when
// `fields` says they were chosen.
pb::TrackOptions TrackOptionsToProto(const TrackerOptions& options,
                                     const TrackOptionsFields& fields);

pb::TrackingState TrackingStateToProto(TrackingState state);
// Empty for UNSPECIFIED and for numbers the proto does not declare.
std::optional<TrackingState> TrackingStateFromProto(pb::TrackingState state);

// A tracked frame's estimate: the result's pose, state, reason and valid rays, the frame's
// timestamp, the map version it was tracked against and the time since it was received. The
// frames dropped before it are the stream's to add (set_dropped) when it is sent.
pb::PoseEstimate PoseEstimateToProto(const TrackingResult& result, double timestamp,
                                     uint64_t map_version, double latency_ms);

}  // namespace plx

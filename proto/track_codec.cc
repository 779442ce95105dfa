#include "proto/track_codec.h"

#include "absl/strings/str_cat.h"
#include "proto/pose_codec.h"

namespace plx {

absl::StatusOr<TrackerOptions> TrackerOptionsFromProto(const pb::TrackOptions& o,
                                                       const std::string& field) {
  if (!pb::TrackOptions::Mode_IsValid(o.mode())) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".mode: unknown mode ", o.mode(), " (UNSPECIFIED, GAUSS_NEWTON or ADAM)"));
  }
  TrackerOptions options = TrackerOptionsForMode(
      o.mode() == pb::TrackOptions::MODE_ADAM ? TrackingMode::kAdam : TrackingMode::kGaussNewton);
  if (o.rays() > 0) options.rays = static_cast<int>(o.rays());
  if (o.iterations() > 0) options.iterations = static_cast<int>(o.iterations());
  if (!pb::TrackOptions::Pixels_IsValid(o.pixels())) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".pixels: unknown choice ", o.pixels(), " (UNSPECIFIED, INFORMATIVE or UNIFORM)"));
  }
  if (o.pixels() == pb::TrackOptions::PIXELS_UNIFORM) options.sampling = PixelSampling::kUniform;
  if (absl::Status s = Tracker::ValidateOptions(options); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": ", s.message()));
  }
  return options;
}

pb::TrackOptions TrackOptionsToProto(const TrackerOptions& options,
                                     const TrackOptionsFields& fields) {
  pb::TrackOptions wire;
  wire.set_mode(options.mode == TrackingMode::kAdam ? pb::TrackOptions::MODE_ADAM
                                                    : pb::TrackOptions::MODE_GAUSS_NEWTON);
  if (fields.rays) wire.set_rays(static_cast<uint32_t>(options.rays));
  if (fields.iterations) wire.set_iterations(static_cast<uint32_t>(options.iterations));
  if (fields.pixels) {
    wire.set_pixels(options.sampling == PixelSampling::kUniform
                        ? pb::TrackOptions::PIXELS_UNIFORM
                        : pb::TrackOptions::PIXELS_INFORMATIVE);
  }
  return wire;
}

pb::TrackingState TrackingStateToProto(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return pb::TRACKING_STATE_OK;
    case TrackingState::kDegraded: return pb::TRACKING_STATE_DEGRADED;
    case TrackingState::kLost: return pb::TRACKING_STATE_LOST;
  }
  return pb::TRACKING_STATE_UNSPECIFIED;
}

std::optional<TrackingState> TrackingStateFromProto(pb::TrackingState state) {
  switch (state) {
    case pb::TRACKING_STATE_OK: return TrackingState::kOk;
    case pb::TRACKING_STATE_DEGRADED: return TrackingState::kDegraded;
    case pb::TRACKING_STATE_LOST: return TrackingState::kLost;
    default: return std::nullopt;
  }
}

pb::PoseEstimate PoseEstimateToProto(const TrackingResult& result, double timestamp,
                                     uint64_t map_version, double latency_ms) {
  pb::PoseEstimate estimate;
  estimate.set_timestamp(timestamp);
  PoseToProto(result.pose, estimate.mutable_pose());
  estimate.set_state(TrackingStateToProto(result.state));
  estimate.set_reason(result.reason);
  estimate.set_valid_rays(static_cast<uint32_t>(result.valid_rays));
  estimate.set_map_version(map_version);
  estimate.set_latency_ms(latency_ms);
  return estimate;
}

}  // namespace plx

#include "proto/track_codec.h"

#include "absl/strings/str_cat.h"

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
  if (absl::Status s = Tracker::ValidateOptions(options); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": ", s.message()));
  }
  return options;
}

pb::TrackingState TrackingStateToProto(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return pb::TRACKING_STATE_OK;
    case TrackingState::kDegraded: return pb::TRACKING_STATE_DEGRADED;
    case TrackingState::kLost: return pb::TRACKING_STATE_LOST;
  }
  return pb::TRACKING_STATE_UNSPECIFIED;
}

}  // namespace plx

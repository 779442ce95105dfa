#include "core/slam/slam_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

SlamState FromTracking(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return SlamState::kOk;
    case TrackingState::kDegraded: return SlamState::kDegraded;
    case TrackingState::kLost: return SlamState::kLost;
  }
  return SlamState::kLost;
}

}  // namespace

const char* SlamStateName(SlamState state) {
  switch (state) {
    case SlamState::kOk: return "OK";
    case SlamState::kDegraded: return "DEGRADED";
    case SlamState::kLost: return "LOST";
    case SlamState::kRelocalised: return "RELOCALISED";
    case SlamState::kWaiting: return "WAITING";
  }
  return "?";
}

BootstrapDepth CountBootstrapDepth(const DepthImage& depth, float max_depth) {
  BootstrapDepth out;
  // NaN fails both comparisons, so a NaN pixel never counts.
  out.valid = std::count_if(depth.data.begin(), depth.data.end(),
                            [max_depth](float d) { return d > 0.0f && d <= max_depth; });
  const auto fraction = static_cast<int64_t>(
      std::ceil(kSlamBootstrapMinDepthFraction * static_cast<double>(depth.num_pixels())));
  out.needed = std::max(fraction, kSlamBootstrapMinDepthPixels);
  return out;
}

absl::Status ValidateSlamTrackerOptions(const SlamTrackerOptions& o) {
  PLX_RETURN_IF_ERROR(Tracker::ValidateOptions(o.tracker));
  PLX_RETURN_IF_ERROR(ValidateKeyframePolicy(o.keyframes));
  if (o.relocalisation_keyframes < 0 || o.relocalisation_keyframes > 64) {
    return absl::InvalidArgumentError(absl::StrCat(
        "relocalisation_keyframes must be in [0, 64], got ", o.relocalisation_keyframes));
  }
  if (!(o.relocalisation_radius_m > 0.0) || !std::isfinite(o.relocalisation_radius_m)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "relocalisation_radius_m must be positive, got ", o.relocalisation_radius_m));
  }
  if (!(o.bootstrap_max_depth > 0.0f) || !std::isfinite(o.bootstrap_max_depth)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "bootstrap_max_depth must be positive, got ", o.bootstrap_max_depth));
  }
  if (o.initial_pose && !o.initial_pose->IsFinite()) {
    return absl::InvalidArgumentError("initial pose is not finite");
  }
  return absl::OkStatus();
}

SlamTracker::SlamTracker(const SlamTrackerOptions& options, Backend* backend)
    : options_(options), backend_(backend), tracker_(nullptr, backend, options.tracker) {}

absl::Status SlamTracker::CheckFrame(const RgbdFrame& frame, const PinholeIntrinsics& k,
                                     const std::optional<SE3>& prior) const {
  if (frame.color.width != k.width || frame.color.height != k.height ||
      frame.depth.width != k.width || frame.depth.height != k.height ||
      frame.color.channels != 3 || frame.depth.channels != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "frame ", counts_.frames, ": colour ", frame.color.width, "x", frame.color.height,
        " and depth ", frame.depth.width, "x", frame.depth.height,
        " do not match the intrinsics ", k.width, "x", k.height));
  }
  if (prior && !prior->IsFinite()) {
    return absl::InvalidArgumentError(
        absl::StrCat("frame ", counts_.frames, ": prior is not finite"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<TrackingResult>> SlamTracker::Relocalise(
    const RgbdFrame& frame, const PinholeIntrinsics& k, const std::optional<SE3>& prior,
    const SlamMapView& view) {
  std::vector<SE3> candidates;
  if (prior) candidates.push_back(*prior);
  // Where the motion before the loss would have carried the camera (a covered lens, a blur),
  // then where it was last seen.
  candidates.push_back(tracker_.Predict(frame.timestamp));
  if (last_good_pose_) candidates.push_back(*last_good_pose_);
  std::vector<StampedPose> keyframes = view.keyframe_poses;
  if (last_good_pose_) {
    const Eigen::Vector3d here = last_good_pose_->translation();
    std::sort(keyframes.begin(), keyframes.end(), [&](const StampedPose& a, const StampedPose& b) {
      return (a.pose.translation() - here).squaredNorm() <
             (b.pose.translation() - here).squaredNorm();
    });
  }
  const int tries =
      std::min<int>(options_.relocalisation_keyframes, static_cast<int>(keyframes.size()));
  for (int i = 0; i < tries; ++i) candidates.push_back(keyframes[i].pose);

  // Candidates in order of how likely they are; the first that tracks OK without wandering far
  // from where it started wins. The adaptive noise scale makes a residual test weak evidence
  // on its own (it stretches to whatever spread it finds), so a start that slid half a metre
  // along a wall is a false match, not a relocalisation.
  TrackerOptions attempt_options = options_.tracker;
  attempt_options.iterations = std::max(attempt_options.iterations, 20);
  attempt_options.constant_velocity = false;
  TrackerOptions verify_options = attempt_options;
  verify_options.adaptive_scale = false;
  verify_options.iterations = 2;
  for (const SE3& start : candidates) {
    Tracker attempt(tracked_map_.get(), backend_, attempt_options);
    attempt.Reset(start, frame.timestamp);
    PLX_ASSIGN_OR_RETURN(TrackingResult r, attempt.Track(frame, k, start));
    if (r.state != TrackingState::kOk) continue;
    if ((r.pose.translation() - start.translation()).norm() > options_.relocalisation_radius_m) {
      continue;
    }
    // Verify at the sensor's own noise: a true match explains the frame within it, a pose that
    // slid along a surface leaves residuals far above it.
    Tracker verify(tracked_map_.get(), backend_, verify_options);
    verify.Reset(r.pose, frame.timestamp);
    PLX_ASSIGN_OR_RETURN(TrackingResult check, verify.Track(frame, k, r.pose));
    if (check.state != TrackingState::kOk) continue;
    return std::optional<TrackingResult>(r);
  }
  return std::optional<TrackingResult>();
}

SlamFrameResult SlamTracker::Bootstrap(const RgbdFrame& frame, const std::optional<SE3>& prior,
                                       SlamFrameResult out) {
  ++counts_.frames;
  const SE3 pose = prior.value_or(options_.initial_pose.value_or(SE3::Identity()));
  out.pose = pose;
  out.tracking.pose = pose;
  const BootstrapDepth depth = CountBootstrapDepth(frame.depth, options_.bootstrap_max_depth);
  if (!depth.enough()) {
    // A map built from it would be too small to track the next frames against: the camera
    // waits, as it is, for a frame that sees enough (a depth camera's first frames, a lens
    // uncovered).
    out.state = SlamState::kWaiting;
    out.reason = absl::StrFormat(
        "waiting for a frame to start the map: %d of %d pixels have depth in (0, %g m], %d "
        "needed",
        depth.valid, frame.depth.num_pixels(), options_.bootstrap_max_depth, depth.needed);
    ++counts_.waiting;
    return out;
  }
  // Keyframe 0: it builds the first version.
  started_ = true;
  tracker_.Reset(pose, frame.timestamp);
  last_good_pose_ = pose;
  out.state = SlamState::kOk;
  out.reason = "first keyframe";
  out.keyframe = true;
  out.keyframes += 1;
  out.tracking.state = TrackingState::kOk;
  ++counts_.ok;
  return out;
}

absl::StatusOr<SlamFrameResult> SlamTracker::Track(const RgbdFrame& frame,
                                                   const PinholeIntrinsics& k,
                                                   const std::optional<SE3>& prior,
                                                   const SlamMapView& view) {
  const auto start = std::chrono::steady_clock::now();
  SlamFrameResult out;
  out.frame = counts_.frames;
  out.timestamp = frame.timestamp;
  out.keyframes = static_cast<int>(view.accepted_keyframes.size());
  out.map_version = view.version;
  if (BootstrapCandidate(view)) return Bootstrap(frame, prior, std::move(out));
  if (view.map == nullptr) {
    // Checked before anything changes, so the caller can hand the same frame in again later.
    return absl::FailedPreconditionError(
        "the map has no published version yet: its first keyframe is still being integrated");
  }
  ++counts_.frames;
  if (!started_) {
    // The camera joins a map it did not bootstrap (one with content, or another camera's
    // first keyframe, perhaps while this one was WAITING): it has to find itself in it.
    started_ = true;
    lost_ = true;
    const SE3 pose = prior.value_or(options_.initial_pose.value_or(SE3::Identity()));
    tracker_.Reset(pose, frame.timestamp);
    last_good_pose_ = pose;
  }
  tracked_map_ = view.map;
  tracker_.set_map(tracked_map_.get());
  std::optional<TrackingResult> result;
  if (lost_) {
    PLX_ASSIGN_OR_RETURN(result, Relocalise(frame, k, prior, view));
    if (result) {
      tracker_.Reset(result->pose, frame.timestamp);
      out.state = SlamState::kRelocalised;
      out.reason = "relocalised";
      lost_ = false;
    } else {
      // Still lost: the prediction (the prior, else where tracking was last good).
      result.emplace();
      result->pose = prior.value_or(tracker_.Predict(frame.timestamp));
      result->state = TrackingState::kLost;
      result->rays = options_.tracker.rays;
      result->reason = "lost: no relocalisation candidate tracked OK";
      out.state = SlamState::kLost;
      out.reason = result->reason;
    }
  } else {
    PLX_ASSIGN_OR_RETURN(TrackingResult tracked, tracker_.Track(frame, k, prior));
    out.state = FromTracking(tracked.state);
    out.reason = tracked.reason;
    result = std::move(tracked);
  }
  out.tracking = *result;
  out.pose = result->pose;
  if (out.state == SlamState::kLost) {
    lost_ = true;
  } else {
    last_good_pose_ = out.pose;
  }
  if (out.state == SlamState::kOk) {
    // While keyframes wait for mapping, the part of the view the map does not render yet is
    // mostly what they will fill in: counting it again would take a keyframe per frame exactly
    // when mapping is behind, and feed the lag it comes from.
    const double unmapped =
        view.mapping_behind || result->rays == 0
            ? 0.0
            : 1.0 - static_cast<double>(result->valid_rays) / result->rays;
    const KeyframeDecision decision = DecideKeyframe(options_.keyframes, view.accepted_keyframes,
                                                     out.pose, frame.timestamp, unmapped);
    if (decision.keyframe) {
      out.keyframe = true;
      out.keyframes += 1;
      out.reason = decision.reason;
    }
  }
  counts_.ok += out.state == SlamState::kOk;
  counts_.degraded += out.state == SlamState::kDegraded;
  counts_.lost += out.state == SlamState::kLost;
  counts_.relocalised += out.state == SlamState::kRelocalised;
  out.milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace plx

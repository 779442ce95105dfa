#include "core/slam/slam_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/elapsed.h"
#include "core/common/percentile.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

using Clock = std::chrono::steady_clock;

// The map tracker's iterations from the odometry's pose: a share of the schedule, one
// iteration per level at least.
int OdometryStartIterations(const SlamTrackerOptions& o) {
  const int share =
      static_cast<int>(std::lround(o.tracker.iterations * o.odometry_start_iteration_share));
  return std::min(o.tracker.iterations, std::max(2, share));
}

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

int OnPathCheckRays(const SlamTrackerOptions& o) {
  const int share = static_cast<int>(std::lround(o.tracker.rays * o.on_path_check_ray_share));
  return std::min(o.tracker.rays, std::max(256, share));
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
  // Below 1 the budget would cut most frames short of the schedule, not the costly ones.
  if (!(o.map_time_budget == 0.0 || (o.map_time_budget >= 1.0 && o.map_time_budget <= 100.0))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "map_time_budget must be 0 (off) or in [1, 100], got ", o.map_time_budget));
  }
  if (!(o.odometry_start_iteration_share > 0.0 && o.odometry_start_iteration_share <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("odometry_start_iteration_share must be in (0, 1], got ",
                     o.odometry_start_iteration_share));
  }
  if (o.new_segment_after_lost_frames < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "new_segment_after_lost_frames must be >= 0, got ", o.new_segment_after_lost_frames));
  }
  if (o.new_segment_after_unconfirmed_frames < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("new_segment_after_unconfirmed_frames must be >= 0, got ",
                     o.new_segment_after_unconfirmed_frames));
  }
  if (!(o.max_seconds_without_map >= 0.0) || !std::isfinite(o.max_seconds_without_map)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_seconds_without_map must be >= 0, got ", o.max_seconds_without_map));
  }
  if (o.max_deferred_frames < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_deferred_frames must be >= 0, got ", o.max_deferred_frames));
  }
  if (o.segment_join_interval < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("segment_join_interval must be >= 1, got ", o.segment_join_interval));
  }
  if (!(o.on_path_check_ray_share > 0.0 && o.on_path_check_ray_share <= 1.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "on_path_check_ray_share must be in (0, 1], got ", o.on_path_check_ray_share));
  }
  if (o.skip_checks_after_failed_check < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "skip_checks_after_failed_check must be >= 0, got ", o.skip_checks_after_failed_check));
  }
  if (o.relocalisation_attempts_per_frame < 1 || o.relocalisation_attempts_per_frame > 16) {
    return absl::InvalidArgumentError(
        absl::StrCat("relocalisation_attempts_per_frame must be in [1, 16], got ",
                     o.relocalisation_attempts_per_frame));
  }
  if (o.feature_relocalisation) {
    PLX_RETURN_IF_ERROR(ValidateFrameFeatureOptions(o.features));
    PLX_RETURN_IF_ERROR(ValidateFeatureRelocaliserOptions(o.feature_relocaliser));
  }
  if (!(o.bootstrap_max_depth > 0.0f) || !std::isfinite(o.bootstrap_max_depth)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "bootstrap_max_depth must be positive, got ", o.bootstrap_max_depth));
  }
  if (o.initial_pose && !o.initial_pose->IsFinite()) {
    return absl::InvalidArgumentError("initial pose is not finite");
  }
  if (o.odometry) {
    PLX_RETURN_IF_ERROR(ValidateOdometryPyramidOptions(o.odometry_pyramid));
    PLX_RETURN_IF_ERROR(ValidateOdometryOptions(o.odometry_options));
  }
  return absl::OkStatus();
}

absl::StatusOr<OdometryPyramid> SlamTracker::PyramidOf(const RgbdFrame& frame,
                                                       const PinholeIntrinsics& k) const {
  if (!options_.odometry) return OdometryPyramid();
  return BuildOdometryPyramid(frame, k, options_.odometry_pyramid);
}

absl::StatusOr<std::optional<OdometryPose>> SlamTracker::RunOdometry(
    const OdometryPyramid& pyramid, double timestamp, const std::optional<SE3>& prior,
    OdometryResult* result) const {
  if (!options_.odometry || !previous_ || !previous_->pose) return std::optional<OdometryPose>();
  const SE3& previous_pose = *previous_->pose;
  // The starting guess: the client's prior, else the last motion scaled to this frame's gap
  // (none after a gap of over a second, or out of order).
  SE3 guess = SE3::Identity();
  const double dt = timestamp - previous_->timestamp;
  if (prior) {
    guess = previous_pose.Inverse() * *prior;
  } else if (last_motion_ && last_motion_dt_ > 0.0 && dt > 0.0 && dt <= 1.0) {
    guess = SE3::Exp(last_motion_->Log() * (dt / last_motion_dt_));
  }
  PLX_ASSIGN_OR_RETURN(*result,
                       EstimateOdometry(previous_->pyramid, pyramid, guess,
                                        options_.odometry_options));
  return std::optional<OdometryPose>(
      OdometryPose{previous_pose * result->reference_T_current, result->ok, result->reason});
}

void SlamTracker::Remember(OdometryPyramid pyramid, const std::optional<SE3>& pose,
                           double timestamp, bool continues) {
  if (!options_.odometry) return;
  if (continues && pose && previous_ && previous_->pose && timestamp > previous_->timestamp) {
    last_motion_ = previous_->pose->Inverse() * *pose;
    last_motion_dt_ = timestamp - previous_->timestamp;
  } else {
    last_motion_.reset();
  }
  previous_ = PreviousFrame{std::move(pyramid), pose, timestamp};
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

absl::StatusOr<std::shared_ptr<const FrameFeatures>> SlamTracker::FeaturesOf(
    const RgbdFrame& frame, const PinholeIntrinsics& k) {
  if (!options_.feature_relocalisation) return std::shared_ptr<const FrameFeatures>();
  if (frame_features_ == nullptr) {
    PLX_ASSIGN_OR_RETURN(FrameFeatures features,
                         ExtractFrameFeatures(frame, k, options_.features));
    frame_features_ = std::make_shared<const FrameFeatures>(std::move(features));
  }
  return frame_features_;
}

absl::StatusOr<std::optional<TrackingResult>> SlamTracker::TryRelocalisationFrom(
    const SE3& start, int iterations, const RgbdFrame& frame, const PinholeIntrinsics& k,
    const PlenoxelMap* map, int rays) {
  if (map == nullptr) map = tracked_map_.get();
  // An attempt counts when it tracks OK without wandering far from where it started. The
  // adaptive noise scale makes a residual test weak evidence on its own (it stretches to
  // whatever spread it finds), so a start that slid half a metre along a wall is a false
  // match, not a relocalisation.
  TrackerOptions attempt_options = options_.tracker;
  attempt_options.iterations = iterations;
  if (rays > 0) attempt_options.rays = rays;
  attempt_options.constant_velocity = false;
  Tracker attempt(map, backend_, attempt_options);
  attempt.Reset(start, frame.timestamp);
  PLX_ASSIGN_OR_RETURN(TrackingResult r, attempt.Track(frame, k, start));
  if (r.state != TrackingState::kOk) return std::optional<TrackingResult>();
  if ((r.pose.translation() - start.translation()).norm() > options_.relocalisation_radius_m) {
    return std::optional<TrackingResult>();
  }
  // Verify at the sensor's own noise: a true match explains the frame within it, a pose that
  // slid along a surface leaves residuals far above it.
  TrackerOptions verify_options = attempt_options;
  verify_options.adaptive_scale = false;
  verify_options.iterations = 2;
  Tracker verify(map, backend_, verify_options);
  verify.Reset(r.pose, frame.timestamp);
  PLX_ASSIGN_OR_RETURN(TrackingResult check, verify.Track(frame, k, r.pose));
  if (check.state != TrackingState::kOk) return std::optional<TrackingResult>();
  return std::optional<TrackingResult>(std::move(r));
}

namespace {
// Frames whose map tracking times make the median of map_time_budget: a few seconds of frames,
// so a room's far side or a rebuild on the other core sets its own pace; no budget before a
// quarter of them.
constexpr size_t kMapTimeWindow = 64;
}  // namespace

double SlamTracker::MapTimeBudgetMs() const {
  if (options_.map_time_budget <= 0.0 || map_times_ms_.size() < kMapTimeWindow / 4) return 0.0;
  return options_.map_time_budget *
         Percentile(std::vector<double>(map_times_ms_.begin(), map_times_ms_.end()), 0.5);
}

void SlamTracker::RecordMapTime(double milliseconds) {
  map_times_ms_.push_back(milliseconds);
  if (map_times_ms_.size() > kMapTimeWindow) map_times_ms_.pop_front();
}

absl::StatusOr<std::optional<FeatureRelocalisation>> SlamTracker::FindByFeatures(
    const RgbdFrame& frame, const PinholeIntrinsics& k, const SlamMapView& view) {
  if (!options_.feature_relocalisation || view.keyframe_features.empty()) {
    return std::optional<FeatureRelocalisation>();
  }
  PLX_ASSIGN_OR_RETURN(std::shared_ptr<const FrameFeatures> features, FeaturesOf(frame, k));
  // Index i is keyframe i: features and refined poses are both in the order accepted.
  std::vector<RelocalisationKeyframe> keyframes;
  const size_t n = std::min(view.keyframe_features.size(), view.keyframe_poses.size());
  for (size_t i = 0; i < n; ++i) {
    keyframes.push_back({view.keyframe_features[i].get(), view.keyframe_poses[i].pose});
  }
  return RelocaliseByFeatures(*features, keyframes, k, options_.feature_relocaliser);
}

absl::StatusOr<std::optional<TrackingResult>> SlamTracker::VerifyFeaturePose(
    const FeatureRelocalisation& found, const RgbdFrame& frame, const PinholeIntrinsics& k,
    std::string* reason, const PlenoxelMap* map, int iterations, int rays) {
  // PnP lands within a few centimetres: the tracker's own iteration count refines it.
  if (iterations <= 0) iterations = options_.tracker.iterations;
  PLX_ASSIGN_OR_RETURN(std::optional<TrackingResult> verified,
                       TryRelocalisationFrom(found.pose, iterations, frame, k, map, rays));
  if (verified) {
    *reason = absl::StrFormat("relocalised by features (keyframe %d: %d of %d matches)",
                              found.keyframe, found.inliers, found.matches);
  }
  return verified;
}

TrackingResult SlamTracker::AdoptVerifiedPlace(TrackingResult place, SlamState state,
                                               std::string reason, double timestamp,
                                               SlamFrameResult* out) {
  tracker_.Reset(place.pose, timestamp);
  lost_with_depth_ = 0;
  out->state = state;
  out->source = PoseSource::kMap;
  out->reason = std::move(reason);
  return place;
}

absl::StatusOr<std::optional<TrackingResult>> SlamTracker::Relocalise(
    const RgbdFrame& frame, const PinholeIntrinsics& k, const std::optional<SE3>& prior,
    const SlamMapView& view, std::string* reason) {
  // Dense attempts are what a LOST frame pays for: at most relocalisation_attempts_per_frame.
  int attempts = options_.relocalisation_attempts_per_frame;
  PLX_ASSIGN_OR_RETURN(const std::optional<FeatureRelocalisation> found,
                       FindByFeatures(frame, k, view));
  if (found) {
    PLX_ASSIGN_OR_RETURN(std::optional<TrackingResult> verified,
                         VerifyFeaturePose(*found, frame, k, reason));
    if (verified) return verified;
    --attempts;
  }

  // Near where the camera was: the prior, where the motion before the loss would have carried
  // it (a covered lens, a blur), where it was last seen, the keyframes nearest to that.
  std::vector<SE3> candidates;
  if (prior) candidates.push_back(*prior);
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

  // This frame's share of the list; the next LOST frame goes on where it stopped. These starts
  // may be centimetres off, but a LOST frame gets the tracker's own schedule, no more: with 20
  // iterations each LOST frame in unseen space cost 2.5x a tracked one (docs/BENCHMARKS.md),
  // and the features find places from further away than these attempts ever did.
  const int count = static_cast<int>(candidates.size());
  attempts = std::min(attempts, count);
  const int iterations = options_.tracker.iterations;
  for (int a = 0; a < attempts; ++a) {
    const int index = (relocalisation_cursor_ + a) % count;
    PLX_ASSIGN_OR_RETURN(std::optional<TrackingResult> r,
                         TryRelocalisationFrom(candidates[index], iterations, frame, k));
    if (r) {
      *reason = "relocalised near the last good pose";
      return r;
    }
  }
  if (attempts > 0) relocalisation_cursor_ = (relocalisation_cursor_ + attempts) % count;
  return std::optional<TrackingResult>();
}

absl::StatusOr<std::optional<TrackingResult>> SlamTracker::TryJoinMain(
    const RgbdFrame& frame, const PinholeIntrinsics& k, const SlamMapView& view,
    std::string* reason) {
  if (view.main == nullptr || view.main->map == nullptr) return std::optional<TrackingResult>();
  PLX_ASSIGN_OR_RETURN(const std::optional<FeatureRelocalisation> found,
                       FindByFeatures(frame, k, *view.main));
  if (!found) return std::optional<TrackingResult>();
  // On a tracked frame's path: the odometry start's share of the schedule (the check at the
  // sensor's noise still decides), so looking for the main map costs about one frame's map
  // tracking.
  return VerifyFeaturePose(*found, frame, k, reason, view.main->map.get(),
                           OdometryStartIterations(options_));
}

bool SlamTracker::NearCarryStart(const SE3& pose) const {
  const SE3 moved = carry_origin_.Inverse() * pose;
  return moved.translation().norm() < options_.keyframes.max_translation_m &&
         Eigen::AngleAxisd(moved.rotation()).angle() < options_.keyframes.max_rotation_rad;
}

absl::StatusOr<TrackingResult> SlamTracker::CarryWithoutMap(const OdometryPyramid& pyramid,
                                                            const RgbdFrame& frame,
                                                            const std::optional<SE3>& prior,
                                                            SlamFrameResult* out) {
  PLX_ASSIGN_OR_RETURN(const std::optional<OdometryPose> odometry,
                       RunOdometry(pyramid, frame.timestamp, prior, &out->odometry));
  TrackingResult r;
  if (odometry && odometry->ok) {
    // Not a keyframe: the map's keyframe rules need the map to say what it covers.
    r.pose = odometry->pose;
    r.state = TrackingState::kDegraded;
    r.reason = "the map's first version is not out yet: the odometry carries the pose";
    out->state = SlamState::kDegraded;
    out->source = PoseSource::kOdometry;
    tracker_.Reset(r.pose, frame.timestamp);
  } else {
    r.pose = prior.value_or(tracker_.Predict(frame.timestamp));
    r.state = TrackingState::kLost;
    r.reason = absl::StrCat("the map's first version is not out yet and the odometry failed: ",
                            odometry ? odometry->reason : "no reference frame");
    out->state = SlamState::kLost;
    out->source = PoseSource::kPrediction;
  }
  out->reason = r.reason;
  return r;
}

void SlamTracker::StartSegment(double timestamp, std::string reason, TrackingResult* result,
                               SlamFrameResult* out) {
  const SE3& pose = result->pose;
  // The prior, else where the camera was last seen, becomes the new segment's origin: nothing
  // ties the two frames (the odometry lost the motion; the motion model's extrapolation over
  // the lost frames is worth less), but a camera that did not move far keeps roughly the same
  // axes for the client until the segment joins the main map.
  out->new_segment = true;
  out->state = SlamState::kOk;
  out->reason = std::move(reason);
  result->state = TrackingState::kOk;
  result->reason.clear();
  out->keyframe = true;
  out->keyframes = 1;
  tracker_.set_map(nullptr);
  tracked_map_.reset();
  tracker_.Reset(pose, timestamp);
  lost_ = false;
  lost_with_depth_ = 0;
  unconfirmed_with_depth_ = 0;
  relocalisation_cursor_ = 0;
  frames_in_segment_ = 0;
  carry_start_ = timestamp;
  carry_origin_ = pose;
  ++counts_.segments_started;
}

SlamFrameResult SlamTracker::Bootstrap(const RgbdFrame& frame, const std::optional<SE3>& prior,
                                       OdometryPyramid pyramid, SlamFrameResult out) {
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
    previous_.reset();
    last_motion_.reset();
    return out;
  }
  Remember(std::move(pyramid), pose, frame.timestamp);
  // Keyframe 0: it builds the first version.
  started_ = true;
  carry_start_ = frame.timestamp;
  carry_origin_ = pose;
  tracker_.Reset(pose, frame.timestamp);
  last_good_pose_ = pose;
  out.state = SlamState::kOk;
  out.reason = "first keyframe";
  out.source = PoseSource::kMap;
  out.keyframe = true;
  out.keyframes += 1;
  out.tracking.state = TrackingState::kOk;
  ++counts_.ok;
  return out;
}

void SlamTracker::FollowCorrection(const SlamMapView& view, SlamFrameResult* out) {
  const SlamMapView* main = view.segment == 0 ? &view : view.main.get();
  const std::shared_ptr<const SlamCorrection> correction =
      main != nullptr ? main->correction : nullptr;
  if (correction != nullptr && correction->generation > correction_generation_) {
    correction_generation_ = correction->generation;
    // A camera in a segment keeps the segment's frame (its join measures main_T_segment in
    // the corrected main map); one in the main map moves with the keyframe it is anchored to.
    // A camera that missed a correction (two came while it was not tracking) moves by the
    // latest only: its poses are then off by what the one it missed moved them.
    const std::optional<SE3> at =
        previous_ && previous_->pose ? previous_->pose : last_good_pose_;
    if (view.segment == 0 && at) {
      const SE3 change = correction->FrameChangeAt(*at);
      if (previous_ && previous_->pose) previous_->pose = change * *previous_->pose;
      if (last_good_pose_) last_good_pose_ = change * *last_good_pose_;
      carry_origin_ = change * carry_origin_;
      tracker_.MoveWorld(change);
      out->correction = correction;
      out->frame_change = change;
    }
  }
  out->correction_generation = correction_generation_;
}

absl::StatusOr<SlamFrameResult> SlamTracker::Track(const RgbdFrame& frame,
                                                   const PinholeIntrinsics& k,
                                                   const std::optional<SE3>& prior,
                                                   const SlamMapView& view) {
  const auto start = Clock::now();
  SlamFrameResult out;
  out.frame = counts_.frames;
  out.timestamp = frame.timestamp;
  out.keyframes = static_cast<int>(view.accepted_keyframes.size());
  out.map_version = view.version;
  out.map_rebuilding = view.map_rebuilding;
  if (!BootstrapCandidate(view) && view.map == nullptr && !CarriesWithoutMap()) {
    // Checked before anything changes, so the caller can hand the same frame in again later.
    return absl::FailedPreconditionError(
        "the map has no published version yet: its first keyframe is still being integrated");
  }
  frame_features_.reset();
  auto stage = Clock::now();
  PLX_ASSIGN_OR_RETURN(OdometryPyramid pyramid, PyramidOf(frame, k));
  out.timings.odometry_ms += MillisecondsSince(stage);
  if (BootstrapCandidate(view)) {
    out = Bootstrap(frame, prior, std::move(pyramid), std::move(out));
    if (out.keyframe) {
      stage = Clock::now();
      PLX_ASSIGN_OR_RETURN(out.features, FeaturesOf(frame, k));
      out.timings.features_ms += MillisecondsSince(stage);
    }
    out.milliseconds = MillisecondsSince(start);
    return out;
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
  FollowCorrection(view, &out);
  tracked_map_ = view.map;
  tracker_.set_map(tracked_map_.get());
  std::optional<TrackingResult> result;
  bool may_be_keyframe = false;
  // The frame's pose is a map pose (or chained to one) that the features did not confirm.
  bool unconfirmed_pose = false;
  if (view.map == nullptr) {
    // Keyframe 0 (of the map or of a segment) is still being integrated.
    stage = Clock::now();
    PLX_ASSIGN_OR_RETURN(result, CarryWithoutMap(pyramid, frame, prior, &out));
    out.timings.odometry_ms += MillisecondsSince(stage);
  } else if (lost_) {
    std::string how;
    const BootstrapDepth depth = CountBootstrapDepth(frame.depth, options_.bootstrap_max_depth);
    // Below the tracker's LOST fraction no dense attempt can track OK, and the features need
    // depth too: a covered lens costs nothing.
    const bool too_little_depth =
        depth.valid < options_.tracker.lost_valid_fraction * frame.depth.num_pixels();
    stage = Clock::now();
    if (!too_little_depth) {
      PLX_ASSIGN_OR_RETURN(result, Relocalise(frame, k, prior, view, &how));
    }
    out.timings.relocalisation_ms += MillisecondsSince(stage);
    if (result) {
      tracker_.Reset(result->pose, frame.timestamp);
      out.state = SlamState::kRelocalised;
      out.source = PoseSource::kMap;
      out.reason = how;
      lost_ = false;
      relocalisation_cursor_ = 0;
    } else {
      // Still lost: the prediction (the prior, else where tracking was last good).
      result.emplace();
      result->pose = prior.value_or(tracker_.Predict(frame.timestamp));
      result->state = TrackingState::kLost;
      result->rays = options_.tracker.rays;
      result->reason =
          too_little_depth
              ? absl::StrFormat("lost: too little depth to relocalise (%d of %d pixels)",
                                depth.valid, frame.depth.num_pixels())
              : "lost: no relocalisation candidate tracked OK";
      out.state = SlamState::kLost;
      out.reason = result->reason;
      // Relocalisation had depth to work with and found nothing, frame after frame: the camera
      // is somewhere this map has not seen. A covered lens (no depth) does not count.
      const int segment_after = options_.new_segment_after_lost_frames;
      if (segment_after > 0 && depth.enough() && ++lost_with_depth_ >= segment_after) {
        result->pose = prior.value_or(last_good_pose_.value_or(result->pose));
        StartSegment(frame.timestamp,
                     absl::StrFormat("new map segment: relocalisation failed on %d frames "
                                     "that had depth to map",
                                     lost_with_depth_),
                     &*result, &out);  // out.source stays the prediction's
      }
    }
  } else if (!options_.odometry) {
    stage = Clock::now();
    PLX_ASSIGN_OR_RETURN(TrackingResult tracked, tracker_.Track(frame, k, prior));
    out.timings.map_ms += MillisecondsSince(stage);
    out.state = FromTracking(tracked.state);
    out.source = out.state == SlamState::kLost ? PoseSource::kPrediction : PoseSource::kMap;
    out.reason = tracked.reason;
    may_be_keyframe = out.state == SlamState::kOk;
    result = std::move(tracked);
  } else {
    // The odometry's pose starts the map tracker (the prior's place when there is none), then
    // the two are fused (core/slam/pose_fusion.h).
    stage = Clock::now();
    PLX_ASSIGN_OR_RETURN(const std::optional<OdometryPose> odometry,
                         RunOdometry(pyramid, frame.timestamp, prior, &out.odometry));
    out.timings.odometry_ms += MillisecondsSince(stage);
    const bool from_odometry = odometry && odometry->ok;
    // The odometry failed (a jump in the stream, a blur, a view it cannot match): the
    // keyframes' features are the cheaper first look. Where they place the frame, the dense
    // check of that place at the sensor's noise is the frame's whole map tracking (the
    // odometry start's share of the schedule); where they find nothing, the map tracker starts
    // from the motion model with its full schedule, as when there are no features.
    std::optional<std::optional<FeatureRelocalisation>> looked;  // set once the features ran
    if (!from_odometry && options_.feature_relocalisation) {
      stage = Clock::now();
      PLX_ASSIGN_OR_RETURN(looked, FindByFeatures(frame, k, view));
      std::optional<TrackingResult> placed;
      std::string how;
      if (*looked) {
        PLX_ASSIGN_OR_RETURN(placed, VerifyFeaturePose(**looked, frame, k, &how, nullptr,
                                                       OdometryStartIterations(options_)));
      }
      out.timings.relocalisation_ms += MillisecondsSince(stage);
      if (placed) {
        const SE3 predicted = prior.value_or(tracker_.Predict(frame.timestamp));
        const bool moved = !PosesAgree(placed->pose, predicted, options_.fusion);
        // A place the features found and the map explains at the sensor's noise may grow the
        // map; a jump may not on its first frame (as every relocalisation).
        may_be_keyframe = !moved;
        result = AdoptVerifiedPlace(
            *std::move(placed), moved ? SlamState::kRelocalised : SlamState::kOk,
            moved ? how
                  : absl::StrCat("the odometry failed; ", how,
                                 " where the motion model expected it"),
            frame.timestamp, &out);
      }
    }
    if (!result) {
      const std::optional<SE3> map_start = from_odometry ? odometry->pose : prior;
      stage = Clock::now();
      tracker_.set_iterations(
          from_odometry ? OdometryStartIterations(options_) : options_.tracker.iterations);
      tracker_.set_time_budget_ms(from_odometry ? MapTimeBudgetMs() : 0.0);
      PLX_ASSIGN_OR_RETURN(TrackingResult tracked, tracker_.Track(frame, k, map_start));
      out.timings.map_ms += MillisecondsSince(stage);
      if (from_odometry) RecordMapTime(tracked.milliseconds);
      FusedPose fused = FusePoses(tracked, odometry, options_.fusion);
      if (unconfirmed_chain_) fused = ChainedToUnconfirmedPose(std::move(fused));
      // The map tracker's motion model follows the pose given out when it is not its own.
      if (fused.source == PoseSource::kOdometry) tracker_.Reset(fused.pose, frame.timestamp);
      out.state = fused.state;
      out.source = fused.source;
      out.reason = fused.reason;
      may_be_keyframe = fused.may_be_keyframe;
      result = std::move(tracked);
      result->pose = fused.pose;
      // The map renders the view but contradicts the odometry's pose (moving things do that,
      // and so does a kidnap the odometry followed with confidence: a jump in the stream that
      // its gates could not tell from motion), or the map's pose has nothing to back it (the
      // odometry failed): the keyframes' features decide. Where they agree with the pose given
      // out, that is all (no dense work); only a place elsewhere costs a dense verification.
      const bool contradicted =
          fused.source == PoseSource::kOdometry && result->cause != TrackingCause::kFewValidRays;
      if (contradicted || fused.confirm) {
        stage = Clock::now();
        std::optional<FeatureRelocalisation> found;
        if (looked) {
          found = *looked;  // looked already: nothing, or a place whose check failed above
        } else {
          PLX_ASSIGN_OR_RETURN(found, FindByFeatures(frame, k, view));
        }
        const bool elsewhere = found && !PosesAgree(found->pose, fused.pose, options_.fusion);
        std::optional<TrackingResult> moved;
        std::string how;
        if (elsewhere && !looked) {
          if (checks_to_skip_ > 0) {
            --checks_to_skip_;  // a check just failed: the stretch the map contradicts goes on
          } else {
            // On a tracked frame's path, after its map tracking: the odometry start's share of
            // the schedule, as above, and on_path_check_ray_share of the rays.
            PLX_ASSIGN_OR_RETURN(moved, VerifyFeaturePose(*found, frame, k, &how, nullptr,
                                                          OdometryStartIterations(options_),
                                                          OnPathCheckRays(options_)));
            if (!moved) checks_to_skip_ = options_.skip_checks_after_failed_check;
          }
        }
        out.timings.relocalisation_ms += MillisecondsSince(stage);
        if (moved) {
          may_be_keyframe = false;
          result = AdoptVerifiedPlace(*std::move(moved), SlamState::kRelocalised, how,
                                      frame.timestamp, &out);
        } else {
          const CheckedPose checked = ApplyFeatureCheck(fused, found.has_value(), !elsewhere);
          out.state = checked.state;
          out.reason = checked.reason;
          may_be_keyframe = checked.may_be_keyframe;
          unconfirmed_pose = checked.unconfirmed;
        }
      }
    }
  }
  // A chain of poses the features never confirm maps nothing (no keyframes): past a bound the
  // camera maps on in a segment of its own from where the chain put it, which joins the main
  // map once a place there is found and verified (what a confirmation would have needed too).
  const int segment_after_unconfirmed = options_.new_segment_after_unconfirmed_frames;
  if (!unconfirmed_pose || segment_after_unconfirmed == 0) {
    unconfirmed_with_depth_ = 0;
  } else if (CountBootstrapDepth(frame.depth, options_.bootstrap_max_depth).enough() &&
             ++unconfirmed_with_depth_ >= segment_after_unconfirmed) {
    StartSegment(frame.timestamp,
                 absl::StrFormat("new map segment: the keyframes' features confirmed none of "
                                 "%d frames chained to an unconfirmed map pose",
                                 unconfirmed_with_depth_),
                 &*result, &out);
    may_be_keyframe = false;  // keyframe 0 of the segment already
    unconfirmed_pose = false;
  }
  // In a segment, tracked there: now and then, look for the main map (bounded: the features
  // and a match; a dense check only where they find a place).
  if (view.segment != 0 && view.map != nullptr && out.state != SlamState::kLost &&
      !out.new_segment && ++frames_in_segment_ % options_.segment_join_interval == 0) {
    std::string how;
    stage = Clock::now();
    PLX_ASSIGN_OR_RETURN(std::optional<TrackingResult> joined,
                         TryJoinMain(frame, k, view, &how));
    out.timings.relocalisation_ms += MillisecondsSince(stage);
    if (joined) {
      out.main_T_segment = joined->pose * result->pose.Inverse();
      tracked_map_ = view.main->map;
      tracker_.set_map(tracked_map_.get());
      tracker_.Reset(joined->pose, frame.timestamp);
      out.state = SlamState::kRelocalised;
      out.source = PoseSource::kMap;
      out.reason = absl::StrCat("joined the main map: ", how);
      may_be_keyframe = false;
      frames_in_segment_ = 0;
      ++counts_.segments_joined;
      result = std::move(joined);
    }
  }
  out.tracking = *result;
  out.pose = result->pose;
  // Motion the map did not confirm since the camera's last keyframe, measured from the last
  // pose given out (a LOST frame's prediction is no motion; the relocalised pose after it
  // carries the whole jump). A new segment or a join starts another chain of poses.
  if (out.new_segment || out.main_T_segment) {
    unconfirmed_ = {};
  } else if (out.state != SlamState::kOk && out.state != SlamState::kLost && last_good_pose_) {
    unconfirmed_.Add(*last_good_pose_, out.pose);
  }
  // The next frames' poses follow from this one (the odometry's reference, the map tracker's
  // start): they stay unconfirmed with it (ChainedToUnconfirmedPose) until the features place
  // one of them. A LOST frame ends the chain (relocalisation verifies its place), so does a
  // new segment (a frame of its own) or a join (verified). Without feature relocalisation
  // nothing could confirm the chain: the rule is the frame's own (FusedPose::confirm).
  unconfirmed_chain_ = options_.feature_relocalisation && unconfirmed_pose &&
                       out.state != SlamState::kLost && !out.new_segment && !out.main_T_segment;
  if (out.state == SlamState::kLost) {
    if (!lost_) relocalisation_cursor_ = 0;  // a new loss starts at the likeliest pose
    lost_ = true;
    Remember(std::move(pyramid), std::nullopt, frame.timestamp);
  } else {
    last_good_pose_ = out.pose;
    if (!out.new_segment) lost_with_depth_ = 0;
    // A relocalised pose is no motion from the previous frame's, nor is a new segment's
    // origin: the jump must not become the next frame's constant-velocity guess.
    Remember(std::move(pyramid), out.pose, frame.timestamp,
             /*continues=*/out.state != SlamState::kRelocalised && !out.new_segment);
  }
  if (out.new_segment) {
    stage = Clock::now();
    PLX_ASSIGN_OR_RETURN(out.features, FeaturesOf(frame, k));
    out.timings.features_ms += MillisecondsSince(stage);
  }
  if (may_be_keyframe) {
    // While keyframes wait for mapping, the part of the view the map does not render yet is
    // mostly what they will fill in: counting it again would take a keyframe per frame exactly
    // when mapping is behind, and feed the lag it comes from.
    const double unmapped =
        view.mapping_behind() || result->rays == 0
            ? 0.0
            : 1.0 - static_cast<double>(result->valid_rays) / result->rays;
    const KeyframeDecision decision = DecideKeyframe(options_.keyframes, view.accepted_keyframes,
                                                     out.pose, frame.timestamp, unmapped);
    const bool behind = decision.keyframe && options_.max_pending_keyframes > 0 &&
                        view.pending_keyframes >= options_.max_pending_keyframes;
    const bool overdue =
        behind && options_.max_deferred_frames > 0 &&
        deferred_frames_ >= options_.max_deferred_frames;
    deferred_frames_ = behind && !overdue ? deferred_frames_ + 1 : 0;
    if (behind && !overdue) {
      const std::string deferred =
          absl::StrFormat("keyframe deferred (%s): %d keyframes wait for mapping",
                          decision.reason, view.pending_keyframes);
      out.reason = out.reason.empty() ? deferred : absl::StrCat(out.reason, "; ", deferred);
    } else if (decision.keyframe) {
      out.keyframe = true;
      out.keyframes += 1;
      out.unconfirmed = std::exchange(unconfirmed_, UnconfirmedMotion{});
      out.reason = overdue ? absl::StrFormat("%s (deferred on %d frames: waits for mapping)",
                                             decision.reason, options_.max_deferred_frames)
                           : decision.reason;
      stage = Clock::now();
      PLX_ASSIGN_OR_RETURN(out.features, FeaturesOf(frame, k));
      out.timings.features_ms += MillisecondsSince(stage);
    }
  }
  // The keyframe the pose is anchored to, should a correction move the keyframes later.
  const SlamMapView* main = view.segment == 0 ? &view : view.main.get();
  if (main != nullptr && (view.segment == 0 || out.main_T_segment)) {
    out.reference_keyframe = AnchorKeyframe(main->keyframe_poses, out.pose);
    if (out.reference_keyframe >= 0) {
      out.reference_keyframe_pose = main->keyframe_poses[out.reference_keyframe].pose;
    }
  }
  counts_.ok += out.state == SlamState::kOk;
  counts_.degraded += out.state == SlamState::kDegraded;
  counts_.lost += out.state == SlamState::kLost;
  counts_.relocalised += out.state == SlamState::kRelocalised;
  out.milliseconds = MillisecondsSince(start);
  return out;
}

}  // namespace plx

#include "core/slam/slam_session.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

SlamState FromTracking(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return SlamState::kOk;
    case TrackingState::kDegraded: return SlamState::kDegraded;
    case TrackingState::kLost: return SlamState::kLost;
  }
  return SlamState::kLost;
}

// Bytes a keyframe keeps for mapping: float RGB + float depth per pixel, and two 32-bit ray
// indices per pixel with valid depth (core/mapping/training_set.h).
int64_t KeyframeBytes(const RgbdFrame& frame) {
  int64_t valid = 0;
  for (float d : frame.depth.data) valid += d > 0.0f;
  return static_cast<int64_t>(frame.color.data.size() + frame.depth.data.size()) * 4 + valid * 8;
}

}  // namespace

const char* SlamStateName(SlamState state) {
  switch (state) {
    case SlamState::kOk: return "OK";
    case SlamState::kDegraded: return "DEGRADED";
    case SlamState::kLost: return "LOST";
    case SlamState::kRelocalised: return "RELOCALISED";
  }
  return "?";
}

SlamOptions DefaultSlamOptions() {
  SlamOptions o;
  // Tracking wants a new keyframe's geometry soon; a publish costs the index, not the bricks.
  o.mapping.min_publish_interval_s = 0.25;
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.window_fraction = 0.5f;
  o.refinement.tracker = o.tracker;
  // Refinement is not latency-bound, and a keyframe can be off by more than a frame's motion:
  // the coarse-to-fine schedule needs room to converge (8 iterations stopped half-way on a
  // 2 cm, 1 degree error in the tests; 20 converge).
  o.refinement.tracker.iterations = 20;
  return o;
}

absl::Status ValidateSlamOptions(const SlamOptions& o) {
  PLX_RETURN_IF_ERROR(Tracker::ValidateOptions(o.tracker));
  PLX_RETURN_IF_ERROR(ValidateMappingSessionOptions(o.mapping));
  PLX_RETURN_IF_ERROR(ValidateKeyframePolicy(o.keyframes));
  PLX_RETURN_IF_ERROR(ValidateKeyframeRefinementOptions(o.refinement));
  if (o.relocalisation_keyframes < 0 || o.relocalisation_keyframes > 64) {
    return absl::InvalidArgumentError(absl::StrCat(
        "relocalisation_keyframes must be in [0, 64], got ", o.relocalisation_keyframes));
  }
  if (!(o.relocalisation_radius_m > 0.0) || !std::isfinite(o.relocalisation_radius_m)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "relocalisation_radius_m must be positive, got ", o.relocalisation_radius_m));
  }
  if (o.mapping_nice < 0 || o.mapping_nice > 19) {
    return absl::InvalidArgumentError(
        absl::StrCat("mapping_nice must be in [0, 19], got ", o.mapping_nice));
  }
  if (o.initial_pose && !o.initial_pose->IsFinite()) {
    return absl::InvalidArgumentError("initial pose is not finite");
  }
  return absl::OkStatus();
}

namespace {

// Lock-step mapping publishes only when the caller's frame waits for it, and clones every
// brick it needs: neither may depend on the clock, or runs would differ.
SlamOptions EffectiveOptions(SlamOptions o) {
  if (o.deterministic) {
    o.mapping.min_publish_interval_s = 1e9;
    o.mapping.max_clones_per_iteration = 0;
  }
  return o;
}

}  // namespace

SlamSession::SlamSession(const SlamOptions& options, Backend* tracking_backend)
    : options_(EffectiveOptions(options)),
      tracking_backend_(tracking_backend),
      tracker_(nullptr, tracking_backend, options.tracker) {}

absl::StatusOr<std::unique_ptr<SlamSession>> SlamSession::Create(
    const SlamOptions& options, Backend* tracking_backend,
    const BackendFactory& make_mapping_backend, std::shared_ptr<const PlenoxelMap> base) {
  PLX_RETURN_IF_ERROR(ValidateSlamOptions(options));
  if (tracking_backend == nullptr || !make_mapping_backend) {
    return absl::InvalidArgumentError("SLAM needs a tracking backend and a mapping backend");
  }
  if (base != nullptr && base->grid.num_bricks() == 0) base = nullptr;  // nothing to extend
  std::unique_ptr<SlamSession> session(new SlamSession(options, tracking_backend));
  PLX_RETURN_IF_ERROR(session->StartMapping(make_mapping_backend, std::move(base)));
  return session;
}

SlamSession::~SlamSession() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (mapping_thread_.joinable()) mapping_thread_.join();
}

absl::Status SlamSession::StartMapping(const BackendFactory& make_backend,
                                       std::shared_ptr<const PlenoxelMap> base) {
  if (base != nullptr) {
    latest_ = base;
    version_ = 1;
    progress_.map_version = 1;
    lost_ = true;  // the first frame has to find itself in the map: a relocalisation
  }
  if (options_.deterministic) {
    PLX_ASSIGN_OR_RETURN(mapping_backend_, make_backend());
    PLX_ASSIGN_OR_RETURN(mapping_, MappingSession::Create(options_.mapping,
                                                          mapping_backend_.get(), base));
    return absl::OkStatus();
  }
  std::promise<absl::Status> started;
  std::future<absl::Status> ready = started.get_future();
  mapping_thread_ = std::thread([this, make_backend, base, &started] {
    MappingLoop(make_backend, base, &started);
  });
  absl::Status status = ready.get();
  if (!status.ok()) {
    mapping_thread_.join();
    return status;
  }
  return absl::OkStatus();
}

void SlamSession::MappingLoop(const BackendFactory& make_backend,
                              std::shared_ptr<const PlenoxelMap> base,
                              std::promise<absl::Status>* started) {
  // Lower this thread's priority before the backend starts its workers: they inherit it, so
  // on a shared CPU the tracker's loops run first and mapping takes the cycles left over.
  if (options_.mapping_nice > 0) {
    setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), options_.mapping_nice);
  }
  {
    absl::StatusOr<std::unique_ptr<Backend>> backend = make_backend();
    if (!backend.ok()) {
      started->set_value(backend.status());
      return;
    }
    mapping_backend_ = *std::move(backend);
    absl::StatusOr<std::unique_ptr<MappingSession>> session =
        MappingSession::Create(options_.mapping, mapping_backend_.get(), base);
    if (!session.ok()) {
      started->set_value(session.status());
      return;
    }
    mapping_ = *std::move(session);
    started->set_value(absl::OkStatus());  // `started` dies with Create's frame after this
  }
  uint64_t seen_wakeups = 0;
  absl::Status status;
  for (;;) {
    bool finishing = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] {
        return stop_ || finishing_ || wakeups_ != seen_wakeups || mapping_->has_work();
      });
      if (stop_) break;
      seen_wakeups = wakeups_;
      finishing = finishing_;
    }
    if (finishing) {
      status = RunMappingToEnd(true);
      break;
    }
    if (!mapping_->has_work()) continue;
    absl::StatusOr<MappingStepResult> step = mapping_->Step();
    status = step.ok() ? AfterStep(*step) : step.status();
    // Out of work: the last iterations are published now, not when the next keyframe comes.
    if (status.ok() && !mapping_->has_work()) status = PublishIfChanged();
    if (!status.ok()) break;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!status.ok()) mapping_error_ = status;
  mapping_done_ = true;
  changed_.notify_all();
}

absl::Status SlamSession::RunMappingToEnd(bool finish) {
  while (mapping_->has_work()) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return absl::OkStatus();
    }
    PLX_ASSIGN_OR_RETURN(MappingStepResult step, mapping_->Step(finish));
    PLX_RETURN_IF_ERROR(AfterStep(step));
  }
  return PublishIfChanged();
}

absl::Status SlamSession::PublishIfChanged() {
  PLX_ASSIGN_OR_RETURN(std::shared_ptr<const PlenoxelMap> version, mapping_->Publish());
  MappingStepResult published;
  if (version != latest_map()) published.published = std::move(version);
  return AfterStep(published);
}

absl::Status SlamSession::AfterStep(const MappingStepResult& step) {
  const MappingSessionProgress p = mapping_->progress();
  std::vector<StampedPose> poses;
  const bool new_version = step.published != nullptr;
  if (new_version && options_.refinement.window > 0 &&
      p.keyframes_integrated > refined_upto_keyframes_ && !mapping_->has_work()) {
    // The new keyframes have had their iterations: align the window to what they built, and let
    // the next steps fit the map to the refined poses.
    refined_upto_keyframes_ = p.keyframes_integrated;
    PLX_ASSIGN_OR_RETURN(KeyframeRefinementResult refined,
                         RefineKeyframePoses(*mapping_, *step.published, *mapping_backend_,
                                             options_.refinement));
    std::lock_guard<std::mutex> lock(mutex_);
    progress_.refined_keyframes += refined.refined;
  }
  const TrainingSet& keyframes = mapping_->keyframes();
  poses.reserve(keyframes.num_frames());
  for (int i = 0; i < keyframes.num_frames(); ++i) {
    poses.push_back({keyframes.frame(i).timestamp, keyframes.pose(i)});
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (new_version) {
    latest_ = step.published;
    ++version_;
  }
  progress_.keyframes_integrated = p.keyframes_integrated;
  progress_.pending_keyframes = p.keyframes_added - p.keyframes_integrated;
  progress_.mapping_iterations = p.iterations;
  progress_.map_version = version_;
  progress_.map_bytes = p.map_bytes;
  keyframe_poses_ = std::move(poses);
  changed_.notify_all();
  return absl::OkStatus();
}

absl::Status SlamSession::MappingError() const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!mapping_error_.ok()) return mapping_error_;
  if (mapping_done_ && !finishing_) return absl::InternalError("the mapping thread stopped");
  return absl::OkStatus();
}

absl::Status SlamSession::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                      const PinholeIntrinsics& k) {
  RgbdFrame keyframe = frame;
  keyframe.ground_truth.reset();  // SLAM never reads it; keep it out of the map's inputs
  const int64_t bytes = KeyframeBytes(keyframe);
  PLX_RETURN_IF_ERROR(mapping_->AddKeyframe(std::move(keyframe), pose, k));
  ++keyframes_;
  accepted_keyframes_.push_back({frame.timestamp, pose});
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakeups_;
    progress_.keyframes = keyframes_;
    progress_.keyframe_bytes += bytes;
    ++progress_.pending_keyframes;
  }
  changed_.notify_all();
  if (options_.deterministic) PLX_RETURN_IF_ERROR(RunMappingToEnd(false));
  return absl::OkStatus();
}

absl::Status SlamSession::WaitForFirstVersion() {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return version_ > 0 || mapping_done_ || !mapping_error_.ok(); });
  if (!mapping_error_.ok()) return mapping_error_;
  if (version_ == 0) return absl::InternalError("mapping stopped before the first map version");
  return absl::OkStatus();
}

absl::StatusOr<std::optional<TrackingResult>> SlamSession::Relocalise(
    const RgbdFrame& frame, const PinholeIntrinsics& k, const std::optional<SE3>& prior) {
  std::vector<SE3> candidates;
  if (prior) candidates.push_back(*prior);
  // Where the motion before the loss would have carried the camera (a covered lens, a blur),
  // then where it was last seen.
  candidates.push_back(tracker_.Predict(frame.timestamp));
  if (last_good_pose_) candidates.push_back(*last_good_pose_);
  std::vector<StampedPose> keyframes = keyframe_poses();
  if (last_good_pose_) {
    const Eigen::Vector3d here = last_good_pose_->translation();
    std::sort(keyframes.begin(), keyframes.end(), [&](const StampedPose& a, const StampedPose& b) {
      return (a.pose.translation() - here).squaredNorm() <
             (b.pose.translation() - here).squaredNorm();
    });
  }
  const int tries = std::min<int>(options_.relocalisation_keyframes,
                                  static_cast<int>(keyframes.size()));
  for (int i = 0; i < tries; ++i) candidates.push_back(keyframes[i].pose);

  // Candidates in order of how likely they are (the prior, the motion model's prediction, where
  // tracking was last good, the keyframes nearest to it); the first that tracks OK without wandering far from where it
  // started wins. The adaptive noise scale makes a residual test weak evidence on its own (it
  // stretches to whatever spread it finds), so a start that slid half a metre along a wall is
  // a false match, not a relocalisation.
  TrackerOptions attempt_options = options_.tracker;
  attempt_options.iterations = std::max(attempt_options.iterations, 20);
  attempt_options.constant_velocity = false;
  TrackerOptions verify_options = attempt_options;
  verify_options.adaptive_scale = false;
  verify_options.iterations = 2;
  for (const SE3& start : candidates) {
    Tracker attempt(tracked_map_.get(), tracking_backend_, attempt_options);
    attempt.Reset(start, frame.timestamp);
    PLX_ASSIGN_OR_RETURN(TrackingResult r, attempt.Track(frame, k, start));
    if (r.state != TrackingState::kOk) continue;
    if ((r.pose.translation() - start.translation()).norm() > options_.relocalisation_radius_m) {
      continue;
    }
    // Verify at the sensor's own noise: a true match explains the frame within it, a pose that
    // slid along a surface leaves residuals far above it.
    Tracker verify(tracked_map_.get(), tracking_backend_, verify_options);
    verify.Reset(r.pose, frame.timestamp);
    PLX_ASSIGN_OR_RETURN(TrackingResult check, verify.Track(frame, k, r.pose));
    if (check.state != TrackingState::kOk) continue;
    return std::optional<TrackingResult>(r);
  }
  return std::optional<TrackingResult>();
}

absl::StatusOr<SlamFrameResult> SlamSession::ProcessFrame(RgbdFrame frame,
                                                          const PinholeIntrinsics& k,
                                                          const std::optional<SE3>& prior) {
  const auto start = std::chrono::steady_clock::now();
  if (finished_) return absl::FailedPreconditionError("the SLAM session has finished");
  if (frame.color.width != k.width || frame.color.height != k.height ||
      frame.depth.width != k.width || frame.depth.height != k.height ||
      frame.color.channels != 3 || frame.depth.channels != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "frame ", frames_, ": colour ", frame.color.width, "x", frame.color.height, " and depth ",
        frame.depth.width, "x", frame.depth.height, " do not match the intrinsics ", k.width,
        "x", k.height));
  }
  if (prior && !prior->IsFinite()) {
    return absl::InvalidArgumentError(absl::StrCat("frame ", frames_, ": prior is not finite"));
  }
  PLX_RETURN_IF_ERROR(MappingError());
  frame.ground_truth.reset();
  SlamFrameResult out;
  out.frame = frames_;
  out.timestamp = frame.timestamp;

  return CatchAllocationFailure("SLAM frame", [&]() -> absl::StatusOr<SlamFrameResult> {
    const bool first = frames_ == 0;
    ++frames_;
    if (first && latest_map() == nullptr) {
      // Bootstrap: the first frame is keyframe 0 and builds the first version.
      const SE3 pose = prior.value_or(options_.initial_pose.value_or(SE3::Identity()));
      PLX_RETURN_IF_ERROR(AddKeyframe(frame, pose, k));
      PLX_RETURN_IF_ERROR(WaitForFirstVersion());
      tracker_.Reset(pose, frame.timestamp);
      last_good_pose_ = pose;
      out.pose = pose;
      out.state = SlamState::kOk;
      out.reason = "first keyframe";
      out.keyframe = true;
      out.tracking.pose = pose;
      out.tracking.state = TrackingState::kOk;
    } else {
      if (first) {
        const SE3 pose = prior.value_or(options_.initial_pose.value_or(SE3::Identity()));
        tracker_.Reset(pose, frame.timestamp);
        last_good_pose_ = pose;
      }
      {
        std::lock_guard<std::mutex> lock(mutex_);
        tracked_map_ = latest_;
        tracked_version_ = version_;
      }
      tracker_.set_map(tracked_map_.get());
      std::optional<TrackingResult> result;
      if (lost_) {
        PLX_ASSIGN_OR_RETURN(result, Relocalise(frame, k, prior));
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
        result = tracked;
      }
      out.tracking = *result;
      out.pose = result->pose;
      if (out.state == SlamState::kLost) {
        lost_ = true;
      } else {
        last_good_pose_ = out.pose;
      }
      if (out.state == SlamState::kOk) {
        const double unmapped =
            result->rays > 0 ? 1.0 - static_cast<double>(result->valid_rays) / result->rays : 1.0;
        const KeyframeDecision decision = DecideKeyframe(
            options_.keyframes, accepted_keyframes_, out.pose, frame.timestamp, unmapped);
        if (decision.keyframe) {
          PLX_RETURN_IF_ERROR(AddKeyframe(frame, out.pose, k));
          out.keyframe = true;
          out.reason = decision.reason;
        }
      }
    }
    out.keyframes = keyframes_;
    out.map_version = tracked_version_;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      progress_.frames = frames_;
      progress_.ok += out.state == SlamState::kOk;
      progress_.degraded += out.state == SlamState::kDegraded;
      progress_.lost += out.state == SlamState::kLost;
      progress_.relocalised += out.state == SlamState::kRelocalised;
    }
    out.milliseconds = MillisecondsSince(start);
    return out;
  });
}

absl::Status SlamSession::Finish() {
  if (finished_) return MappingError();
  finished_ = true;
  if (options_.deterministic) return RunMappingToEnd(true);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    finishing_ = true;
  }
  changed_.notify_all();
  if (mapping_thread_.joinable()) mapping_thread_.join();
  std::lock_guard<std::mutex> lock(mutex_);
  return mapping_error_;
}

std::shared_ptr<const PlenoxelMap> SlamSession::latest_map() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return latest_;
}

std::vector<StampedPose> SlamSession::keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return keyframe_poses_;
}

SlamProgress SlamSession::progress() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return progress_;
}

}  // namespace plx

#include "core/slam/slam_session.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/elapsed.h"
#include "core/common/status_macros.h"
#include "core/common/thread_priority.h"

namespace plx {

SlamOptions DefaultSlamOptions() {
  SlamOptions o;
  // Tracking wants a new keyframe's geometry at once; a publish costs the index, not the
  // bricks, and its cost still spaces publishes out (MappingSessionOptions).
  o.mapping.min_publish_interval_s = 0.0;
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.window_fraction = 0.5f;
  o.refinement.tracker = o.tracker;
  // Refinement is not latency-bound, and a keyframe can be off by more than a frame's motion:
  // the coarse-to-fine schedule needs room to converge (8 iterations stopped half-way on a
  // 2 cm, 1 degree error in the tests; 20 converge).
  o.refinement.tracker.iterations = 20;
  return o;
}

SlamOptions SlamOptionsFor(float voxel_size, const TrackerOptions& tracker) {
  SlamOptions o = DefaultSlamOptions();
  const MapperOptions defaults = o.mapping.mapper;
  o.mapping.mapper = MapperOptionsForVoxelSize(voxel_size);
  o.mapping.mapper.window_keyframes = defaults.window_keyframes;
  o.mapping.mapper.window_fraction = defaults.window_fraction;
  o.tracker = tracker;
  const int refine_iterations = o.refinement.tracker.iterations;
  o.refinement.tracker = tracker;
  o.refinement.tracker.iterations = std::max(refine_iterations, tracker.iterations);
  return o;
}

absl::Status ValidateSlamOptions(const SlamOptions& o) {
  const SlamSplitOptions split = SplitSlamOptions(o);
  PLX_RETURN_IF_ERROR(ValidateSlamTrackerOptions(split.tracker));
  PLX_RETURN_IF_ERROR(ValidateSlamMapperOptions(split.mapper));
  if (o.max_pending_keyframes < 0 || o.max_pending_keyframes > kMaxPendingKeyframes) {
    return absl::InvalidArgumentError(absl::StrCat("max_pending_keyframes must be in [0, ",
                                                   kMaxPendingKeyframes, "], got ",
                                                   o.max_pending_keyframes));
  }
  if (o.live_source && o.deterministic) {
    return absl::InvalidArgumentError(
        "live_source and deterministic exclude each other (lock-step waits for mapping)");
  }
  if (o.mapping_nice < 0 || o.mapping_nice > 19) {
    return absl::InvalidArgumentError(
        absl::StrCat("mapping_nice must be in [0, 19], got ", o.mapping_nice));
  }
  return absl::OkStatus();
}

SlamSession::SlamSession(const SlamOptions& options, Backend* tracking_backend,
                         std::shared_ptr<const PlenoxelMap> base)
    : options_(options),
      split_(SplitSlamOptions(options)),
      tracker_(split_.tracker, tracking_backend),
      // The mapper numbers its versions itself; a base map is its version 1.
      coordinator_(split_.mapper, split_.gate, base, base != nullptr ? 1 : 0) {}

absl::StatusOr<std::unique_ptr<SlamSession>> SlamSession::Create(
    const SlamOptions& options, Backend* tracking_backend,
    const BackendFactory& make_mapping_backend, std::shared_ptr<const PlenoxelMap> base) {
  PLX_RETURN_IF_ERROR(ValidateSlamOptions(options));
  if (tracking_backend == nullptr || !make_mapping_backend) {
    return absl::InvalidArgumentError("SLAM needs a tracking backend and a mapping backend");
  }
  if (base != nullptr && base->grid.num_bricks() == 0) base = nullptr;  // nothing to extend
  // A session that extends a map starts lost: its first frame has to find itself in it (the
  // tracker sees the base as the map's first version).
  std::unique_ptr<SlamSession> session(
      new SlamSession(options, tracking_backend, std::move(base)));
  PLX_RETURN_IF_ERROR(session->StartMapping(make_mapping_backend));
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

void SlamSession::NotifyChanged() {
  // Under the lock, so a waiter between its predicate check and its wait cannot miss it.
  std::lock_guard<std::mutex> lock(mutex_);
  changed_.notify_all();
}

absl::Status SlamSession::StartMapping(const BackendFactory& make_backend) {
  if (split_.gate.lock_step) {
    PLX_ASSIGN_OR_RETURN(mapping_backend_, make_backend());
    return coordinator_.StartMapper(mapping_backend_.get());
  }
  std::promise<absl::Status> started;
  std::future<absl::Status> ready = started.get_future();
  mapping_thread_ =
      std::thread([this, make_backend, &started] { MappingLoop(make_backend, &started); });
  absl::Status status = ready.get();
  if (!status.ok()) {
    mapping_thread_.join();
    return status;
  }
  return absl::OkStatus();
}

void SlamSession::MappingLoop(const BackendFactory& make_backend,
                              std::promise<absl::Status>* started) {
  // Lower this thread's priority before the backend starts its workers: they inherit it, so
  // on a shared CPU the tracker's loops run first and mapping takes the cycles left over.
  // Best effort: refused, mapping shares the cores equally, which costs latency, not results.
  (void)LowerCurrentThreadPriority(options_.mapping_nice);
  {
    absl::StatusOr<std::unique_ptr<Backend>> backend = make_backend();
    absl::Status status = backend.status();
    if (status.ok()) {
      mapping_backend_ = *std::move(backend);
      status = coordinator_.StartMapper(mapping_backend_.get());
    }
    started->set_value(status);  // `started` dies with Create's frame after this
    if (!status.ok()) return;
  }
  uint64_t seen_wakeups = 0;
  bool more = false;  // the last step left work
  absl::Status status;
  for (;;) {
    bool finishing = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || finishing_ || wakeups_ != seen_wakeups || more; });
      if (stop_) break;
      seen_wakeups = wakeups_;
      finishing = finishing_;
    }
    if (finishing) {
      status = RunMappingToEnd(true);
      break;
    }
    absl::StatusOr<SlamStepResult> step = coordinator_.Step(SlamStepMode::kMap);
    status = step.status();
    more = step.ok() && !step->out_of_work;
    NotifyChanged();
    if (!status.ok()) break;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!status.ok()) mapping_error_ = status;
  mapping_done_ = true;
  changed_.notify_all();
}

absl::Status SlamSession::RunMappingToEnd(bool finish) {
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return absl::OkStatus();
    }
    PLX_ASSIGN_OR_RETURN(const SlamStepResult step,
                         coordinator_.Step(finish ? SlamStepMode::kFinish : SlamStepMode::kMap));
    NotifyChanged();
    if (step.out_of_work) return absl::OkStatus();
  }
}

absl::Status SlamSession::MappingError() const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!mapping_error_.ok()) return mapping_error_;
  if (mapping_done_ && !finishing_) return absl::InternalError("the mapping thread stopped");
  return absl::OkStatus();
}

absl::Status SlamSession::AfterQueued(bool keyframe) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakeups_;
  }
  changed_.notify_all();
  // The camera's next frame in its segment: a version there unless the odometry carries it.
  const bool needs_version = !tracker_.CarriesWithoutMap();
  if (!split_.gate.lock_step) {
    // After a join without a keyframe the main map may have many keyframes to integrate: the
    // camera goes on (its keyframes are deferred meanwhile), it does not wait for them.
    return keyframe ? WaitForMapping(needs_version) : absl::OkStatus();
  }
  PLX_RETURN_IF_ERROR(RunMappingToEnd(false));
  if (keyframe && !coordinator_.MayCameraProceed(segment_, needs_version)) {
    return absl::InternalError("mapping stopped before the camera could go on");
  }
  return absl::OkStatus();
}

absl::Status SlamSession::WaitForMapping(bool needs_version) {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] {
    return coordinator_.MayCameraProceed(segment_, needs_version) || mapping_done_ ||
           !mapping_error_.ok();
  });
  if (!mapping_error_.ok()) return mapping_error_;
  if (!coordinator_.MayCameraProceed(segment_, needs_version)) {
    return absl::InternalError("mapping stopped before the camera could go on");
  }
  return absl::OkStatus();
}

absl::StatusOr<SlamFrameResult> SlamSession::ProcessFrame(RgbdFrame frame,
                                                          const PinholeIntrinsics& k,
                                                          const std::optional<SE3>& prior) {
  const auto start = std::chrono::steady_clock::now();
  if (finished_) return absl::FailedPreconditionError("the SLAM session has finished");
  PLX_RETURN_IF_ERROR(tracker_.CheckFrame(frame, k, prior));
  PLX_RETURN_IF_ERROR(MappingError());
  frame.ground_truth.reset();
  return CatchAllocationFailure("SLAM frame", [&]() -> absl::StatusOr<SlamFrameResult> {
    if (!split_.gate.lock_step && tracker_.NeedsVersion(coordinator_.View(segment_))) {
      // The odometry carried the camera as far as it may without a map (or the camera joins
      // a map whose first keyframe is not integrated yet): this frame waits for the version.
      PLX_RETURN_IF_ERROR(WaitForMapping(/*needs_version=*/true));
    }
    PLX_ASSIGN_OR_RETURN(SlamFrameResult out,
                         tracker_.Track(frame, k, prior, coordinator_.View(segment_)));
    // One camera: its keyframes are the map's in order (camera 0).
    PLX_ASSIGN_OR_RETURN(const bool queued,
                         coordinator_.Accept(frame, k, &out, &segment_, /*camera=*/0));
    if (queued) PLX_RETURN_IF_ERROR(AfterQueued(out.keyframe));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      counts_ = tracker_.counts();
    }
    out.milliseconds = MillisecondsSince(start);
    return out;
  });
}

absl::Status SlamSession::Finish() {
  if (finished_) return MappingError();
  finished_ = true;
  if (split_.gate.lock_step) return RunMappingToEnd(true);
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
  return coordinator_.latest().map;
}

std::vector<StampedPose> SlamSession::keyframe_poses() const {
  return coordinator_.keyframe_poses();
}

std::vector<LoopEdge> SlamSession::loops() const { return coordinator_.loops(); }

SlamProgress SlamSession::progress() const {
  SlamProgress p;
  p.mapping = coordinator_.progress();
  p.segments = coordinator_.segments();
  std::lock_guard<std::mutex> lock(mutex_);
  p.tracking = counts_;
  return p;
}

}  // namespace plx

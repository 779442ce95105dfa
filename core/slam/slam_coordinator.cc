#include "core/slam/slam_coordinator.h"

#include <algorithm>
#include <utility>

#include "core/common/status_macros.h"
#include "core/slam/slam_session.h"

namespace plx {

void ApplyLockStepMappingPolicy(SlamMapperOptions* options) {
  options->mapping.min_publish_interval_s = 1e9;
  options->mapping.max_clones_per_iteration = 0;
}

SlamSplitOptions SplitSlamOptions(const SlamOptions& o) {
  SlamSplitOptions out;
  out.tracker.tracker = o.tracker;
  out.tracker.keyframes = o.keyframes;
  out.tracker.relocalisation_keyframes = o.relocalisation_keyframes;
  out.tracker.relocalisation_radius_m = o.relocalisation_radius_m;
  out.tracker.odometry = o.odometry;
  out.tracker.feature_relocalisation = o.feature_relocalisation;
  // Lock-step maps every keyframe before the next frame: nothing is ever left pending.
  out.tracker.max_pending_keyframes = o.deterministic ? 0 : o.max_pending_keyframes;
  out.tracker.initial_pose = o.initial_pose;
  // A pixel helps the bootstrap only if the tracker uses it and the mapper maps it.
  out.tracker.bootstrap_max_depth =
      std::min(o.tracker.params.max_depth, o.mapping.mapper.allocation.max_depth);

  out.mapper.mapping = o.mapping;
  out.mapper.refinement = o.refinement;
  if (o.deterministic) ApplyLockStepMappingPolicy(&out.mapper);

  out.gate.lock_step = o.deterministic;
  out.gate.max_pending_keyframes = out.tracker.max_pending_keyframes;
  return out;
}

SlamCoordinator::SlamCoordinator(const SlamMapperOptions& mapper_options,
                                 const SlamGateOptions& gate,
                                 std::shared_ptr<const PlenoxelMap> base, int64_t base_version,
                                 SlamPublisher publisher)
    : mapper_options_(mapper_options), gate_(gate), publisher_(std::move(publisher)) {
  if (base != nullptr && base->grid.num_bricks() == 0) base = nullptr;  // nothing to extend
  base_ = base;
  published_ = {std::move(base), base_version};
  progress_.map_version = base_version;
}

bool SlamCoordinator::mapper_started() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mapper_ != nullptr;
}

absl::Status SlamCoordinator::StartMapper(Backend* backend) {
  if (mapper_started()) return absl::FailedPreconditionError("the SLAM mapper has started");
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<SlamMapper> mapper,
                       SlamMapper::Create(mapper_options_, backend, base_));
  std::lock_guard<std::mutex> lock(mutex_);
  // Under the lock: a keyframe added meanwhile goes to early_ and is handed over here too, in
  // the order the cameras added them.
  for (const EarlyKeyframe& k : early_) {
    PLX_RETURN_IF_ERROR(mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
  }
  early_.clear();
  mapper_ = std::move(mapper);
  return absl::OkStatus();
}

absl::Status SlamCoordinator::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                          const PinholeIntrinsics& k,
                                          std::shared_ptr<const FrameFeatures> features) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (mapper_ == nullptr) {
    // The mapper is made by the step-runner, with its backend (the daemon's first task).
    early_.push_back({frame, pose, k});
    early_.back().frame.ground_truth.reset();
  } else {
    PLX_RETURN_IF_ERROR(mapper_->AddKeyframe(frame, pose, k));
  }
  keyframe_features_.push_back(std::move(features));
  ++progress_.keyframes;
  ++progress_.pending_keyframes;
  has_work_ = true;
  progress_.idle = false;
  return absl::OkStatus();
}

absl::StatusOr<SlamStepResult> SlamCoordinator::Step(SlamStepMode mode) {
  SlamMapper* mapper = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    mapper = mapper_.get();
  }
  if (mapper == nullptr) return absl::FailedPreconditionError("StartMapper before Step");
  SlamStepResult out;
  const bool drain = mode == SlamStepMode::kDrain;
  // Draining: only the keyframes already accepted are integrated; the rest of the iteration
  // budget is not spent, so the map is saved soon.
  const bool work = drain ? mapper->progress().pending_keyframes > 0 : mapper->has_work();
  if (work) {
    PLX_RETURN_IF_ERROR(mapper->Step(/*finish=*/mode != SlamStepMode::kMap).status());
    out.stepped = true;
  }
  out.out_of_work =
      !mapper->has_work() || (drain && mapper->progress().pending_keyframes == 0);
  // Out of work: what the last iterations changed is published now, not at the next keyframe
  // (a lock-step camera waits for exactly this).
  if (out.out_of_work) PLX_RETURN_IF_ERROR(mapper->PublishIfChanged());

  // Every new version gets the map's number (the publisher's, else the mapper's own).
  const SlamMapVersion latest = mapper->latest();
  const int integrated = mapper->progress().keyframes_integrated;
  int64_t number = latest.version;
  if (latest.map != nullptr && latest.version != handed_mapper_version_) {
    if (publisher_) {
      PLX_ASSIGN_OR_RETURN(number, publisher_(latest.map, integrated - integrated_at_publish_));
    }
    handed_mapper_version_ = latest.version;
    integrated_at_publish_ = integrated;
    out.published = true;
  }

  std::lock_guard<std::mutex> lock(mutex_);
  if (out.published) published_ = {latest.map, number};
  has_work_ = mapper->has_work();
  const int keyframes = progress_.keyframes;
  progress_ = mapper->progress();
  progress_.keyframes = keyframes;  // the same once early_ is handed over; counted on add
  progress_.pending_keyframes = keyframes - progress_.keyframes_integrated;
  progress_.map_version = published_.version;
  progress_.idle = IdleLocked();
  return out;
}

bool SlamCoordinator::IdleLocked() const {
  return mapper_ != nullptr && !has_work_ && early_.empty() && progress_.pending_keyframes == 0;
}

SlamMapView SlamCoordinator::View() const {
  SlamMapView view;
  std::lock_guard<std::mutex> lock(mutex_);
  view.map = published_.map;
  view.version = published_.map != nullptr ? published_.version : 0;
  if (mapper_ == nullptr) {
    for (const EarlyKeyframe& k : early_) {
      view.accepted_keyframes.push_back({k.frame.timestamp, k.pose});
    }
  } else {
    view.accepted_keyframes = mapper_->accepted_keyframes();
    view.keyframe_poses = mapper_->keyframe_poses();
    view.keyframe_features = keyframe_features_;
  }
  view.pending_keyframes = progress_.pending_keyframes;
  return view;
}

bool SlamCoordinator::MayCameraProceed() const {
  return MayCameraProceed(gate_.max_pending_keyframes);
}

bool SlamCoordinator::MayCameraProceed(int max_pending_keyframes) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (progress_.pending_keyframes > max_pending_keyframes) return false;
  if (published_.map == nullptr) return false;  // a first version is needed either way
  return !gate_.lock_step || IdleLocked();
}

SlamMapperProgress SlamCoordinator::progress() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return progress_;
}

SlamMapVersion SlamCoordinator::latest() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return published_;
}

std::vector<StampedPose> SlamCoordinator::keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mapper_ == nullptr ? std::vector<StampedPose>{} : mapper_->keyframe_poses();
}

}  // namespace plx

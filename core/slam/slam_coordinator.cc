#include "core/slam/slam_coordinator.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
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
  out.tracker.new_segment_after_lost_frames = o.new_segment_after_lost_frames;
  out.tracker.segment_join_interval = o.segment_join_interval;
  // Lock-step maps keyframe 0 before the next frame: nothing to carry (and no timing).
  if (o.deterministic) out.tracker.max_seconds_without_map = 0.0;
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
  auto main = std::make_unique<Segment>();
  main->published = {std::move(base), base_version};
  main->progress.map_version = base_version;
  segments_.push_back(std::move(main));
}

bool SlamCoordinator::mapper_started() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return started_;
}

absl::Status SlamCoordinator::StartMapper(Backend* backend) {
  if (mapper_started()) return absl::FailedPreconditionError("the SLAM mapper has started");
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<SlamMapper> mapper,
                       SlamMapper::Create(mapper_options_, backend, base_));
  std::lock_guard<std::mutex> lock(mutex_);
  backend_ = backend;
  started_ = true;
  // Under the lock: a keyframe added meanwhile goes to `early` and is handed over here too, in
  // the order the cameras added them.
  Segment& main = *segments_[0];
  for (const EarlyKeyframe& k : main.early) {
    PLX_RETURN_IF_ERROR(mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
  }
  main.early.clear();
  main.mapper = std::move(mapper);
  return absl::OkStatus();
}

absl::Status SlamCoordinator::AddKeyframeLocked(const RgbdFrame& frame, const SE3& pose,
                                                const PinholeIntrinsics& k,
                                                std::shared_ptr<const FrameFeatures> features,
                                                Segment* to, bool keep) {
  if (to->mapper == nullptr) {
    // A mapper is made by the step-runner, with its backend (the daemon's first task).
    to->early.push_back({frame, pose, k});
    to->early.back().frame.ground_truth.reset();
  } else {
    PLX_RETURN_IF_ERROR(to->mapper->AddKeyframe(frame, pose, k));
  }
  if (keep) {
    to->kept.push_back({frame, pose, k});
    to->kept.back().frame.ground_truth.reset();
  }
  to->features.push_back(std::move(features));
  ++to->progress.keyframes;
  ++to->progress.pending_keyframes;
  to->has_work = true;
  to->progress.idle = false;
  return absl::OkStatus();
}

absl::Status SlamCoordinator::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                          const PinholeIntrinsics& k,
                                          std::shared_ptr<const FrameFeatures> features,
                                          int segment) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment < 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return absl::InvalidArgumentError(absl::StrCat("no open map segment ", segment));
  }
  return AddKeyframeLocked(frame, pose, k, std::move(features), segments_[segment].get(),
                           /*keep=*/segment != 0);
}

absl::Status SlamCoordinator::JoinLocked(int segment, const SE3& main_T_segment) {
  if (segment <= 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return absl::InvalidArgumentError(absl::StrCat("no open map segment ", segment, " to join"));
  }
  Segment& from = *segments_[segment];
  // The poses mapping refined so far (integrated keyframes), else as accepted.
  const std::vector<StampedPose> refined =
      from.mapper != nullptr ? from.mapper->keyframe_poses() : std::vector<StampedPose>{};
  for (size_t i = 0; i < from.kept.size(); ++i) {
    const SE3 pose = i < refined.size() ? refined[i].pose : from.kept[i].pose;
    PLX_RETURN_IF_ERROR(AddKeyframeLocked(from.kept[i].frame, main_T_segment * pose,
                                          from.kept[i].intrinsics, from.features[i],
                                          segments_[0].get(), /*keep=*/false));
  }
  from.joined = true;
  from.kept.clear();
  from.early.clear();
  from.has_work = false;
  ++segment_counts_.joined;
  return absl::OkStatus();
}

absl::StatusOr<bool> SlamCoordinator::Accept(const RgbdFrame& frame,
                                             const PinholeIntrinsics& k,
                                             SlamFrameResult* result, int* segment) {
  std::lock_guard<std::mutex> lock(mutex_);
  bool queued = false;
  if (result->new_segment) {
    segments_.push_back(std::make_unique<Segment>());
    *segment = static_cast<int>(segments_.size()) - 1;
    ++segment_counts_.started;
  } else if (result->main_T_segment && *segment != 0) {
    PLX_RETURN_IF_ERROR(JoinLocked(*segment, *result->main_T_segment));
    *segment = 0;
    queued = true;
  }
  result->segment = *segment;
  if (result->keyframe) {
    PLX_RETURN_IF_ERROR(AddKeyframeLocked(frame, result->pose, k, result->features,
                                          segments_[*segment].get(), /*keep=*/*segment != 0));
    queued = true;
  }
  return queued;
}

absl::StatusOr<SlamCoordinator::Segment*> SlamCoordinator::SegmentToStep(SlamStepMode mode,
                                                                          bool* main) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!started_) return absl::FailedPreconditionError("StartMapper before Step");
  // The main map, then segments, and only while cameras stream (finishing spends nothing on a
  // map that is not saved).
  const size_t count = mode == SlamStepMode::kMap ? segments_.size() : 1;
  for (size_t i = 1; i < count; ++i) {
    Segment& s = *segments_[i];
    if (s.joined) {
      s.mapper.reset();  // not in use: only the step-runner steps it, and it is here
    } else if (s.mapper == nullptr && !s.early.empty()) {
      PLX_ASSIGN_OR_RETURN(s.mapper, SlamMapper::Create(mapper_options_, backend_));
      for (const EarlyKeyframe& k : s.early) {
        PLX_RETURN_IF_ERROR(s.mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
      }
      s.early.clear();
    }
  }
  // Integration before iterations: a camera tracking in a segment carries on odometry until
  // its keyframes are in, while the main map's iteration budget may last seconds.
  const bool drain = mode == SlamStepMode::kDrain;
  for (const bool integrating : {true, false}) {
    if (drain && !integrating) break;
    for (size_t i = 0; i < count; ++i) {
      Segment& s = *segments_[i];
      if (s.joined || s.mapper == nullptr) continue;
      if (integrating ? s.progress.pending_keyframes > 0 : s.has_work) {
        *main = i == 0;
        return &s;
      }
    }
  }
  *main = true;
  return segments_[0].get();  // out of work: the main map publishes what is left
}

absl::StatusOr<SlamStepResult> SlamCoordinator::Step(SlamStepMode mode) {
  bool main = true;
  PLX_ASSIGN_OR_RETURN(Segment * segment, SegmentToStep(mode, &main));
  PLX_ASSIGN_OR_RETURN(SlamStepResult out, StepSegment(segment, main, mode));
  // Out of work only once every map is (SegmentToStep chose the main map last).
  if (!main) out.out_of_work = false;
  return out;
}

absl::StatusOr<SlamStepResult> SlamCoordinator::StepSegment(Segment* segment, bool main,
                                                            SlamStepMode mode) {
  SlamMapper* mapper = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    mapper = segment->mapper.get();
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

  // Every new version of the main map gets the map's number (the publisher's, else the
  // mapper's own); a segment's versions keep the mapper's.
  const SlamMapVersion latest = mapper->latest();
  const int integrated = mapper->progress().keyframes_integrated;
  int64_t number = latest.version;
  if (latest.map != nullptr && latest.version != segment->handed_mapper_version) {
    if (publisher_ && main) {
      PLX_ASSIGN_OR_RETURN(
          number, publisher_(latest.map, integrated - segment->integrated_at_publish));
    }
    segment->handed_mapper_version = latest.version;
    segment->integrated_at_publish = integrated;
    out.published = true;
  }

  std::lock_guard<std::mutex> lock(mutex_);
  if (out.published) segment->published = {latest.map, number};
  segment->has_work = mapper->has_work();
  const int keyframes = segment->progress.keyframes;
  segment->progress = mapper->progress();
  segment->progress.keyframes = keyframes;  // the same once `early` is handed over
  segment->progress.pending_keyframes = keyframes - segment->progress.keyframes_integrated;
  segment->progress.map_version = segment->published.version;
  segment->progress.idle = IdleLocked(*segment);
  return out;
}

bool SlamCoordinator::IdleLocked(const Segment& segment) const {
  return segment.mapper != nullptr && !segment.has_work && segment.early.empty() &&
         segment.progress.pending_keyframes == 0;
}

SlamMapView SlamCoordinator::ViewLocked(int segment) const {
  SlamMapView view;
  const Segment& s = *segments_[segment];
  view.segment = segment;
  view.map = s.published.map;
  view.version = s.published.map != nullptr ? s.published.version : 0;
  if (s.mapper == nullptr) {
    for (const EarlyKeyframe& k : s.early) {
      view.accepted_keyframes.push_back({k.frame.timestamp, k.pose});
    }
  } else {
    view.accepted_keyframes = s.mapper->accepted_keyframes();
    view.keyframe_poses = s.mapper->keyframe_poses();
    view.keyframe_features = s.features;
  }
  view.pending_keyframes = s.progress.pending_keyframes;
  return view;
}

SlamMapView SlamCoordinator::View(int segment) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment <= 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return ViewLocked(0);
  }
  SlamMapView view = ViewLocked(segment);
  view.main = std::make_shared<const SlamMapView>(ViewLocked(0));
  return view;
}

bool SlamCoordinator::MayCameraProceed(int segment, bool needs_version) const {
  return MayCameraProceed(gate_.max_pending_keyframes, segment, needs_version);
}

bool SlamCoordinator::MayCameraProceed(int max_pending_keyframes, int segment,
                                       bool needs_version) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment < 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    segment = 0;
  }
  const Segment& s = *segments_[segment];
  if (s.progress.pending_keyframes > max_pending_keyframes) return false;
  if (needs_version && s.published.map == nullptr) return false;
  return !gate_.lock_step || IdleLocked(s);
}

SlamMapperProgress SlamCoordinator::progress() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segments_[0]->progress;
}

SlamMapVersion SlamCoordinator::latest() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segments_[0]->published;
}

std::vector<StampedPose> SlamCoordinator::keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  const Segment& main = *segments_[0];
  return main.mapper == nullptr ? std::vector<StampedPose>{} : main.mapper->keyframe_poses();
}

SlamSegmentCounts SlamCoordinator::segments() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segment_counts_;
}

}  // namespace plx

#include "core/slam/slam_mapper.h"

#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace plx {

absl::Status ValidateSlamMapperOptions(const SlamMapperOptions& options) {
  PLX_RETURN_IF_ERROR(ValidateMappingSessionOptions(options.mapping));
  PLX_RETURN_IF_ERROR(ValidateLoopClosureOptions(options.loop_closure));
  if (!(options.rebuild_iteration_share >= 0.0 && options.rebuild_iteration_share <= 1.0)) {
    return absl::InvalidArgumentError("rebuild_iteration_share must be in [0, 1]");
  }
  if (!(options.in_place_max_shift_m >= 0.0) || !std::isfinite(options.in_place_max_shift_m)) {
    return absl::InvalidArgumentError("in_place_max_shift_m must be a non-negative distance");
  }
  PLX_RETURN_IF_ERROR(ValidateRebuildSeedOptions(options.rebuild_seed));
  return ValidateKeyframeRefinementOptions(options.refinement);
}

int64_t SlamKeyframeBytes(const RgbdFrame& frame) {
  int64_t valid = 0;
  for (float d : frame.depth.data) valid += d > 0.0f;
  return static_cast<int64_t>(frame.color.data.size() + frame.depth.data.size()) * 4 + valid * 8;
}

SlamMapper::SlamMapper(const SlamMapperOptions& options, Backend* backend,
                       std::unique_ptr<MappingSession> mapping,
                       std::shared_ptr<const PlenoxelMap> base)
    : options_(options), backend_(backend), mapping_(std::move(mapping)) {
  if (base != nullptr) {
    latest_ = {std::move(base), 1};
    progress_.map_version = 1;
  }
}

absl::StatusOr<std::unique_ptr<SlamMapper>> SlamMapper::Create(
    const SlamMapperOptions& options, Backend* backend, std::shared_ptr<const PlenoxelMap> base) {
  PLX_RETURN_IF_ERROR(ValidateSlamMapperOptions(options));
  if (backend == nullptr) return absl::InvalidArgumentError("SLAM mapping needs a backend");
  if (base != nullptr && base->grid.num_bricks() == 0) base = nullptr;  // nothing to extend
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<MappingSession> mapping,
                       MappingSession::Create(options.mapping, backend, base));
  return std::unique_ptr<SlamMapper>(
      new SlamMapper(options, backend, std::move(mapping), std::move(base)));
}

absl::Status SlamMapper::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                     const PinholeIntrinsics& k, bool earns_iterations) {
  RgbdFrame keyframe = frame;
  keyframe.ground_truth.reset();  // SLAM never reads it; keep it out of the map's inputs
  const int64_t bytes = SlamKeyframeBytes(keyframe);
  // Under the lock, so keyframe i of the mapping session is accepted_[i] whichever cameras add.
  std::lock_guard<std::mutex> lock(mutex_);
  PLX_RETURN_IF_ERROR(mapping_->AddKeyframe(std::move(keyframe), pose, k, earns_iterations));
  accepted_.push_back({frame.timestamp, pose});
  ++progress_.keyframes;
  ++progress_.pending_keyframes;
  progress_.keyframe_bytes += bytes;
  return absl::OkStatus();
}

bool SlamMapper::has_work() const { return mapping_->has_work(); }

absl::StatusOr<bool> SlamMapper::Step(bool finish) {
  PLX_ASSIGN_OR_RETURN(MappingStepResult step, mapping_->Step(finish));
  const bool published = step.published != nullptr;
  PLX_RETURN_IF_ERROR(AfterStep(std::move(step.published)));
  return published;
}

absl::Status SlamMapper::RunToEnd(bool finish) {
  while (mapping_->has_work()) PLX_RETURN_IF_ERROR(Step(finish).status());
  return PublishIfChanged();
}

absl::Status SlamMapper::PublishIfChanged() {
  PLX_ASSIGN_OR_RETURN(std::shared_ptr<const PlenoxelMap> version, mapping_->Publish());
  if (version == latest().map) version = nullptr;
  return AfterStep(std::move(version));
}

absl::Status SlamMapper::AfterStep(std::shared_ptr<const PlenoxelMap> published) {
  const MappingSessionProgress p = mapping_->progress();
  int refined = 0;
  if (published != nullptr && options_.refinement.window > 0 &&
      p.keyframes_integrated > refined_upto_keyframes_ && !mapping_->has_work()) {
    // The new keyframes have had their iterations: align the window to what they built, and let
    // the next steps fit the map to the refined poses.
    refined_upto_keyframes_ = p.keyframes_integrated;
    PLX_ASSIGN_OR_RETURN(KeyframeRefinementResult r,
                         RefineKeyframePoses(*mapping_, *published, *backend_,
                                             options_.refinement));
    refined = r.refined;
  }
  const TrainingSet& keyframes = mapping_->keyframes();
  std::vector<StampedPose> poses;
  poses.reserve(keyframes.num_frames());
  for (int i = 0; i < keyframes.num_frames(); ++i) {
    poses.push_back({keyframes.frame(i).timestamp, keyframes.pose(i)});
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (published != nullptr) latest_ = {std::move(published), latest_.version + 1};
  progress_.refined_keyframes += refined;
  progress_.keyframes_integrated = p.keyframes_integrated;
  progress_.pending_keyframes = progress_.keyframes - p.keyframes_integrated;
  progress_.mapping_iterations = p.iterations;
  progress_.iteration_budget = p.iteration_budget;
  progress_.map_version = latest_.version;
  progress_.map_bytes = p.map_bytes;
  progress_.last_publish_s = p.last_publish_s;
  refined_ = std::move(poses);
  return absl::OkStatus();
}

absl::StatusOr<KeyframeRefinementResult> SlamMapper::RefineAllKeyframes(
    const std::vector<uint8_t>& only) {
  PLX_RETURN_IF_ERROR(PublishIfChanged());
  const std::shared_ptr<const PlenoxelMap> map = latest().map;
  if (map == nullptr) return KeyframeRefinementResult{};
  std::vector<int> which;
  for (int i = 0; i < mapping_->keyframes().num_frames(); ++i) {
    if (only.empty() || (i < static_cast<int>(only.size()) && only[i] != 0)) which.push_back(i);
  }
  PLX_ASSIGN_OR_RETURN(
      KeyframeRefinementResult r,
      RefineKeyframeList(*mapping_, *map, *backend_, options_.refinement, which));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    progress_.refined_keyframes += r.refined;
  }
  PLX_RETURN_IF_ERROR(AfterStep(nullptr));  // the refined poses
  return r;
}

absl::Status SlamMapper::MoveKeyframes(const std::vector<SE3>& poses, int extra_iterations) {
  const int n = mapping_->keyframes().num_frames();
  if (static_cast<int>(poses.size()) != n) {
    return absl::InvalidArgumentError(absl::StrCat("moving ", n, " keyframes needs ", n,
                                                   " poses, got ", poses.size()));
  }
  for (int i = 0; i < n; ++i) PLX_RETURN_IF_ERROR(mapping_->SetKeyframePose(i, poses[i]));
  mapping_->GrantIterations(extra_iterations);
  return AfterStep(nullptr);
}

SlamMapVersion SlamMapper::latest() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return latest_;
}

std::vector<StampedPose> SlamMapper::accepted_keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return accepted_;
}

std::vector<StampedPose> SlamMapper::keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return refined_;
}

std::vector<SE3> SlamMapper::all_keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<SE3> poses;
  poses.reserve(accepted_.size());
  for (size_t i = 0; i < accepted_.size(); ++i) {
    poses.push_back(i < refined_.size() ? refined_[i].pose : accepted_[i].pose);
  }
  return poses;
}

SlamMapperProgress SlamMapper::progress() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return progress_;
}

}  // namespace plx

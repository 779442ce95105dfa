#include "proto/integrate_codec.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace plx {

absl::StatusOr<MappingSessionOptions> MappingSessionOptionsFromProto(
    const pb::IntegrateOptions& o, float voxel_size, int64_t max_map_bytes) {
  MappingSessionOptions options;
  options.mapper = MapperOptionsForVoxelSize(voxel_size);
  if (o.rays_per_iteration() > static_cast<uint32_t>(kMaxBatchSize)) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.rays_per_iteration: at most ", kMaxBatchSize));
  }
  if (o.rays_per_iteration() > 0) {
    options.mapper.batch_size = static_cast<int>(o.rays_per_iteration());
  }
  // Exactly 0 means the default; anything else must be a usable depth.
  if (!(std::isfinite(o.max_depth()) && o.max_depth() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.max_depth: must be finite and > 0 metres (0 = the default), got ", o.max_depth()));
  }
  if (o.max_depth() > 0) {
    options.mapper.allocation.max_depth = o.max_depth();
    options.mapper.fusion.max_depth = o.max_depth();
  }
  if (o.iterations_per_keyframe() > static_cast<uint32_t>(kMaxIterationsPerKeyframe)) {
    return absl::InvalidArgumentError(absl::StrCat("options.iterations_per_keyframe: at most ",
                                                   kMaxIterationsPerKeyframe));
  }
  if (o.iterations_per_keyframe() > 0) {
    options.iterations_per_keyframe = static_cast<int>(o.iterations_per_keyframe());
  }
  options.mapper.max_map_bytes = max_map_bytes;
  if (absl::Status s = ValidateMappingSessionOptions(options); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("options: ", s.message()));
  }
  return options;
}

pb::IntegrateOptions IntegrateOptionsToProto(const MappingSessionOptions& options) {
  pb::IntegrateOptions wire;
  wire.set_iterations_per_keyframe(static_cast<uint32_t>(options.iterations_per_keyframe));
  wire.set_rays_per_iteration(static_cast<uint32_t>(options.mapper.batch_size));
  wire.set_max_depth(options.mapper.allocation.max_depth);
  return wire;
}

pb::MappingProgress MappingProgressToProto(const MappingSessionProgress& p,
                                           const std::string& job_id, uint64_t map_version,
                                           double elapsed_s) {
  pb::MappingProgress progress;
  progress.set_job_id(job_id);
  progress.set_keyframes_integrated(static_cast<uint32_t>(p.keyframes_integrated));
  progress.set_iterations(static_cast<uint32_t>(p.iterations));
  progress.set_train_psnr(p.last_batch.psnr);
  progress.set_train_depth_l1_m(p.last_batch.depth_l1_m);
  progress.set_map_version(map_version);
  progress.set_elapsed_s(elapsed_s);
  return progress;
}

}  // namespace plx

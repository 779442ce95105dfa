#include "core/mapping/training_set.h"

#include "absl/strings/str_cat.h"
#include "core/geometry/kernel_camera.h"
#include "core/geometry/world_pose.h"

namespace plx {

absl::Status TrainingSet::AddFrame(RgbdFrame frame, const SE3& world_T_camera,
                                   const PinholeIntrinsics& k, double max_depth) {
  if (frame.color.width != k.width || frame.color.height != k.height ||
      frame.depth.width != k.width || frame.depth.height != k.height ||
      frame.color.channels != 3 || frame.depth.channels != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "keyframe at t=", frame.timestamp, ": colour ", frame.color.width, "x",
        frame.color.height, "x", frame.color.channels, " and depth ", frame.depth.width, "x",
        frame.depth.height, " do not match intrinsics ", k.width, "x", k.height));
  }
  // Finite and inside the world: a camera beyond it would allocate bricks whose coordinates
  // wrap around, and the map could not be saved and loaded again.
  if (absl::Status s = CheckPoseInsideWorld(world_T_camera,
                                            absl::StrCat("keyframe at t=", frame.timestamp,
                                                         ": pose"));
      !s.ok()) {
    return s;
  }
  if (frames_.size() >= (1u << 20)) return absl::ResourceExhaustedError("too many keyframes");
  const uint32_t index = static_cast<uint32_t>(frames_.size());
  const float max_d = static_cast<float>(max_depth);
  first_ray_.push_back(num_rays());
  const UnifiedVector<float>& depth = frame.depth.data;
  for (size_t p = 0; p < depth.size(); ++p) {
    if (depth[p] > 0.0f && depth[p] <= max_d) {
      ray_frame_.push_back(index);
      ray_pixel_.push_back(static_cast<uint32_t>(p));
    }
  }
  frames_.push_back(std::move(frame));
  poses_.push_back(world_T_camera);
  intrinsics_.push_back(k);
  TrainingFrameView view;
  view.camera = ToKernelCamera(world_T_camera, k);
  view.color = frames_.back().color.data.data();
  view.depth = frames_.back().depth.data.data();
  views_.push_back(view);
  return absl::OkStatus();
}

absl::Status TrainingSet::SetPose(int i, const SE3& world_T_camera) {
  if (i < 0 || i >= num_frames()) {
    return absl::OutOfRangeError(
        absl::StrCat("no keyframe ", i, " (", num_frames(), " keyframes)"));
  }
  if (!world_T_camera.IsFinite()) {
    return absl::InvalidArgumentError(absl::StrCat("keyframe ", i, ": pose is not finite"));
  }
  poses_[i] = world_T_camera;
  views_[i].camera = ToKernelCamera(world_T_camera, intrinsics_[i]);
  return absl::OkStatus();
}

TrainingRaysView TrainingSet::rays_view(int recent_frames) const {
  TrainingRaysView v;
  v.frames = views_.data();
  v.ray_frame = ray_frame_.data();
  v.ray_pixel = ray_pixel_.data();
  v.num_rays = num_rays();
  if (recent_frames > 0 && recent_frames < num_frames()) {
    v.recent_begin = first_ray_[num_frames() - recent_frames];
  }
  return v;
}

}  // namespace plx

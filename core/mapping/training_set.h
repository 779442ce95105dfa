// Keyframes prepared for mapping: decoded images kept on the host, their kernel views, and the
// list of every pixel with valid depth (the rays batches are drawn from).
#pragma once

#include <deque>
#include <vector>

#include "absl/status/status.h"
#include "core/common/unified_allocator.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/kernels/kernel_types.h"

namespace plx {

class TrainingSet {
 public:
  // Adds a keyframe observed from world_T_camera. Pixels with depth outside
  // (0, max_depth] are left out of the ray list. Checks image sizes against the intrinsics.
  absl::Status AddFrame(RgbdFrame frame, const SE3& world_T_camera,
                        const PinholeIntrinsics& intrinsics, double max_depth);

  int num_frames() const { return static_cast<int>(frames_.size()); }
  int64_t num_rays() const { return static_cast<int64_t>(ray_frame_.size()); }
  const UnifiedVector<TrainingFrameView>& frame_views() const { return views_; }
  const RgbdFrame& frame(int i) const { return frames_[i]; }
  const SE3& pose(int i) const { return poses_[i]; }
  const PinholeIntrinsics& intrinsics(int i) const { return intrinsics_[i]; }

  // Moves keyframe i to a refined pose (SLAM's keyframe pose refinement); its rays follow.
  absl::Status SetPose(int i, const SE3& world_T_camera);

  // Valid until the next AddFrame. With recent_frames > 0, the view's recent range holds the
  // rays of the last recent_frames keyframes (TrainingRaysView::recent_begin).
  TrainingRaysView rays_view(int recent_frames = 0) const;

 private:
  std::deque<RgbdFrame> frames_;  // deque: image buffers never move when frames are added
  std::vector<SE3> poses_;
  std::vector<PinholeIntrinsics> intrinsics_;
  // Kernels read these (and the frames' images) on the backend: UnifiedVector.
  UnifiedVector<TrainingFrameView> views_;
  UnifiedVector<uint32_t> ray_frame_;
  UnifiedVector<uint32_t> ray_pixel_;
  std::vector<int64_t> first_ray_;  // per keyframe: the index of its first ray
};

}  // namespace plx

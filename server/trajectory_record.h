// What the web viewer shows of a map's SLAM streams (web/viewer_source.h CameraTrack): for each
// stream (one camera) its current pose and the way it came, and the job's refined keyframe
// poses. The streams write it as they track frames, the viewer reads snapshots from HTTP
// threads. Bounded whatever a stream's length: a path keeps at most kMaxPathPoints positions
// (when full, every second one is dropped and later frames are kept at half the rate, so the
// whole trajectory stays in view at a coarser spacing), and at most kMaxCameras cameras are kept
// (the oldest closed one goes first).
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "core/geometry/se3.h"
#include "core/slam/slam_tracker.h"
#include "web/viewer_source.h"

namespace plx::server {

class TrajectoryRecord {
 public:
  static constexpr size_t kMaxPathPoints = 4096;
  static constexpr size_t kMaxCameras = 64;
  static constexpr size_t kMaxKeyframes = 4096;

  // A stream joined: its camera's id.
  int AddCamera();
  // A frame of camera `id` was tracked. `label` is the frame's camera_id (may be empty).
  void Record(int id, const std::string& label, double timestamp, const SE3& pose,
              SlamState state);
  // The camera's stream ended.
  void Close(int id);
  // The job's refined keyframe poses (the newest kMaxKeyframes are kept) and its loop edges
  // (those between kept keyframes).
  void SetKeyframes(const std::vector<StampedPose>& keyframes,
                    const std::vector<std::pair<int, int>>& loops = {});

  std::vector<web::CameraTrack> Cameras() const;
  std::vector<SE3> Keyframes() const;
  std::vector<std::pair<int, int>> Loops() const;  // indices into Keyframes()

 private:
  struct Camera {
    web::CameraTrack track;
    int64_t stride = 1;  // a frame's position is kept when frames % stride == 0
  };
  Camera* FindLocked(int id);

  mutable std::mutex mutex_;
  std::deque<Camera> cameras_;
  std::vector<SE3> keyframes_;
  std::vector<std::pair<int, int>> loops_;
  int next_id_ = 0;
};

}  // namespace plx::server

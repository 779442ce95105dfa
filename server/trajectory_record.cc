#include "server/trajectory_record.h"

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace plx::server {

int TrajectoryRecord::AddCamera() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (cameras_.size() >= kMaxCameras) {
    // The oldest closed camera makes room; with every one still open (more streams than the
    // bound), the oldest.
    auto closed = std::find_if(cameras_.begin(), cameras_.end(),
                               [](const Camera& c) { return !c.track.active; });
    cameras_.erase(closed != cameras_.end() ? closed : cameras_.begin());
  }
  Camera camera;
  camera.track.id = next_id_++;
  camera.track.label = absl::StrCat("camera ", camera.track.id);
  camera.track.active = true;
  camera.track.state = "WAITING";
  cameras_.push_back(std::move(camera));
  return cameras_.back().track.id;
}

TrajectoryRecord::Camera* TrajectoryRecord::FindLocked(int id) {
  for (Camera& c : cameras_) {
    if (c.track.id == id) return &c;
  }
  return nullptr;  // dropped to make room
}

void TrajectoryRecord::Record(int id, const std::string& label, double timestamp,
                              const SE3& pose, SlamState state) {
  std::lock_guard<std::mutex> lock(mutex_);
  Camera* camera = FindLocked(id);
  if (camera == nullptr) return;
  web::CameraTrack& t = camera->track;
  if (!label.empty() && t.frames == 0) t.label = label.substr(0, 64);
  t.timestamp = timestamp;
  t.pose = pose;
  t.state = SlamStateName(state);  // OK, DEGRADED, LOST, RELOCALISED
  if (t.frames % camera->stride == 0) {
    if (t.path.size() >= kMaxPathPoints) {
      // Keep every second position (the first stays), then keep frames at half the rate.
      size_t kept = 0;
      for (size_t i = 0; i < t.path.size(); i += 2) t.path[kept++] = t.path[i];
      t.path.resize(kept);
      camera->stride *= 2;
    }
    t.path.push_back(pose.translation());
  }
  ++t.frames;
}

void TrajectoryRecord::Close(int id) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (Camera* camera = FindLocked(id)) camera->track.active = false;
}

void TrajectoryRecord::SetKeyframes(const std::vector<StampedPose>& keyframes,
                                    const std::vector<std::pair<int, int>>& loops) {
  std::lock_guard<std::mutex> lock(mutex_);
  keyframes_.clear();
  loops_.clear();
  const size_t first = keyframes.size() > kMaxKeyframes ? keyframes.size() - kMaxKeyframes : 0;
  for (size_t i = first; i < keyframes.size(); ++i) keyframes_.push_back(keyframes[i].pose);
  const int begin = static_cast<int>(first), end = static_cast<int>(keyframes.size());
  for (const auto& [from, to] : loops) {
    if (from >= begin && to >= begin && from < end && to < end) {
      loops_.emplace_back(from - begin, to - begin);
    }
  }
}

std::vector<web::CameraTrack> TrajectoryRecord::Cameras() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<web::CameraTrack> out;
  out.reserve(cameras_.size());
  for (const Camera& c : cameras_) {
    out.push_back(c.track);
    // The path may have skipped the newest frames (stride): it always ends where the camera is.
    if (c.track.frames > 0 &&
        (out.back().path.empty() || out.back().path.back() != c.track.pose.translation())) {
      out.back().path.push_back(c.track.pose.translation());
    }
  }
  return out;
}

std::vector<SE3> TrajectoryRecord::Keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return keyframes_;
}

std::vector<std::pair<int, int>> TrajectoryRecord::Loops() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return loops_;
}

}  // namespace plx::server

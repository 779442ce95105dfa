#include "core/slam/map_segment_poses.h"

namespace plx {

std::map<int, SE3> SegmentJoins(const std::vector<SlamFrameResult>& results) {
  std::map<int, SE3> joins;
  for (size_t i = 1; i < results.size(); ++i) {
    const int left = results[i - 1].segment;
    if (results[i].main_T_segment && left != 0) joins[left] = *results[i].main_T_segment;
  }
  return joins;
}

std::vector<StampedPose> PosesInMainMap(const std::vector<SlamFrameResult>& results) {
  const std::map<int, SE3> joins = SegmentJoins(results);
  std::vector<StampedPose> poses;
  poses.reserve(results.size());
  for (const SlamFrameResult& r : results) {
    const auto join = joins.find(r.segment);
    poses.push_back({r.timestamp, join == joins.end() ? r.pose : join->second * r.pose});
  }
  return poses;
}

std::vector<StampedPose> CorrectedPoses(const std::vector<SlamFrameResult>& results,
                                        const std::vector<StampedPose>& keyframes) {
  std::vector<StampedPose> poses = PosesInMainMap(results);
  for (size_t i = 0; i < results.size(); ++i) {
    const SlamFrameResult& r = results[i];
    if (r.segment != 0 || r.reference_keyframe < 0 ||
        r.reference_keyframe >= static_cast<int>(keyframes.size())) {
      continue;
    }
    poses[i].pose = keyframes[r.reference_keyframe].pose * r.reference_keyframe_pose.Inverse() *
                    r.pose;
  }
  return poses;
}

std::vector<StampedPose> FollowCorrections(const std::vector<SlamFrameResult>& results,
                                           const std::vector<SlamCorrection>& corrections) {
  std::vector<StampedPose> poses = PosesInMainMap(results);
  std::map<int, int> join_generation;  // segment -> the generation its join was measured in
  for (size_t i = 1; i < results.size(); ++i) {
    const int left = results[i - 1].segment;
    if (results[i].main_T_segment && left != 0) {
      join_generation[left] = results[i].correction_generation;
    }
  }
  for (size_t i = 0; i < results.size(); ++i) {
    const SlamFrameResult& r = results[i];
    int generation = r.correction_generation;
    if (r.segment != 0) {
      const auto join = join_generation.find(r.segment);
      if (join == join_generation.end()) continue;
      generation = join->second;
    }
    for (const SlamCorrection& c : corrections) {
      if (c.generation > generation) poses[i].pose = c.Move(poses[i].pose);
    }
  }
  return poses;
}

}  // namespace plx

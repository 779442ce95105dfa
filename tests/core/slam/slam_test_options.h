// The SLAM options the core SLAM suites share: small and quick (2 cm voxels, 1024 tracking
// rays, 30 mapping iterations per keyframe), lock-step so the numbers are the same run to run.
#pragma once

#include "core/slam/slam_session.h"

namespace plx::testing {

inline SlamOptions SmallLockStepSlamOptions() {
  SlamOptions o = DefaultSlamOptions();
  o.deterministic = true;
  o.tracker.rays = 1024;
  o.mapping.mapper = MapperOptionsForVoxelSize(0.02f);
  o.mapping.mapper.window_keyframes = 5;
  o.mapping.mapper.batch_size = 2048;
  o.mapping.iterations_per_keyframe = 30;
  o.refinement.tracker.rays = o.tracker.rays;
  return o;
}

}  // namespace plx::testing

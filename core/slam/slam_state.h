// A SLAM frame's state, shared by the tracker (core/slam/slam_tracker.h) and the front-end's
// fusion rule (core/slam/pose_fusion.h).
#pragma once

namespace plx {

// kWaiting: no map yet and the frame has too little valid depth to start one (BootstrapDepth);
// its pose is the initial pose, it is never a keyframe. Appended last: the daemon's metrics and
// proto enum follow this order.
enum class SlamState { kOk, kDegraded, kLost, kRelocalised, kWaiting };
const char* SlamStateName(SlamState state);

}  // namespace plx

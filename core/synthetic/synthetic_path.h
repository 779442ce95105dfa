// Camera paths through the synthetic scenes (core/synthetic/synthetic_scene.h), as exact
// world_T_camera poses at any time (OpenCV camera axes, x right, y down, z forward; the camera
// never rolls). The circle is the default sequence's path; the others are hard cases for SLAM
// (issue 21): fast head turns, and a walk out of the part of the room the first frames saw;
// and figure eights for loop closure (issue 22), in the room and through two rooms.
#pragma once

#include <string_view>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"
#include "core/synthetic/synthetic_scene.h"

namespace plx {

enum class SyntheticPath {
  // A camera circling the room centre at head height (an ellipse of 1 m x 0.7 m), looking back
  // across the centre and ~15 degrees down at floor, boxes and walls. Smooth and periodic (one
  // turn every 12 s): about 30 degrees of yaw and 0.35-0.5 m of travel per second.
  kCircle,
  // The circle's travel with a headset user's head turns on top: yaw swings of +-38 degrees
  // every 2.4 s, eased in over the first second. Added to the circle's own turning, the yaw
  // rate peaks at 130-135 degrees/s (4.4 degrees per frame at 30 fps) once per swing.
  kHeadTurns,
  // Starts at the -x end looking at the -x wall and the cabinet (1.5 s, swaying a little),
  // then walks 1.2 m towards +x while turning 180 degrees (4 s), then looks around the +x half
  // (the +x wall, the table-height box, the floor in front of them) from then on. From about
  // 2.8 s on, nearly all of every view is room the first 1.5 s never saw.
  kWalkOut,
  // A figure eight (a lemniscate of Gerono) through the room centre, walked forwards: lobes to
  // x = +-1.5 m and y = +-0.8 m, one turn every 20 s, looking along the travel and ~15 degrees
  // down (peak 0.69 m/s and 60 degrees/s at the lobes' ends). The centre is crossed twice per
  // turn at headings ~85 degrees apart; the second turn revisits the first's views: a loop
  // whose two halves drift in opposite directions of turning (issue 22's data).
  kFigureEight,
  // A figure eight through the two rooms of SyntheticSceneKind::kTwoRooms, one lobe in each:
  // lobes to x = +-3.6 m and y = +-1 m, one turn every 30 s, through the doorway at ~29 degrees
  // to the partition twice per turn, looking along the travel and ~15 degrees down (peak
  // about 0.86 m/s). Each pass through the doorway turns the view from one room to the other
  // within a second, and the second turn revisits both rooms: loops in two places that share
  // their walls' textures.
  kTwoRoomEight,
};

// The scene a path walks through: kTwoRooms for kTwoRoomEight, kRoom for the others.
SyntheticSceneKind SyntheticPathScene(SyntheticPath path);

// "circle", "head-turns", "walk-out", "figure-eight", "two-room-eight".
const char* SyntheticPathName(SyntheticPath path);
// The inverse of SyntheticPathName; InvalidArgument listing the names otherwise.
absl::StatusOr<SyntheticPath> ParseSyntheticPath(std::string_view name);

// Ground-truth world_T_camera of `path` at `seconds` after the start (any seconds >= 0; every
// path goes on for ever).
SE3 SyntheticPathPose(SyntheticPath path, double seconds);

// The circle (SyntheticPath::kCircle) at `seconds`.
SE3 SyntheticCameraPoseAtTime(double seconds);

}  // namespace plx

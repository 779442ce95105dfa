#include "core/synthetic/synthetic_path.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Core>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

constexpr double kDegree = M_PI / 180.0;

// Camera-to-world rotation of a camera at `eye` looking at `target` with world +z up, in
// OpenCV axes (x right, y down, z forward).
Eigen::Matrix3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  const Eigen::Vector3d forward = (target - eye).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d rotation;
  rotation.col(0) = right;
  rotation.col(1) = down;
  rotation.col(2) = forward;
  return rotation;
}

// The pose at `eye` looking along `heading` (radians from world +x towards +y) and `pitch`
// (radians, negative looks down).
SE3 LookAlong(const Eigen::Vector3d& eye, double heading, double pitch) {
  const Eigen::Vector3d forward(std::cos(pitch) * std::cos(heading),
                                std::cos(pitch) * std::sin(heading), std::sin(pitch));
  return SE3(LookAt(eye, eye + forward), eye);
}

// 0 at x <= 0, 1 at x >= 1, with zero slope at both ends (3x^2 - 2x^3) ...
double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

// ... and with zero slope and curvature at both ends (6x^5 - 15x^4 + 10x^3): a walk that
// starts and stops without a jerk.
double SmootherStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * x * (x * (6.0 * x - 15.0) + 10.0);
}

// ---------------------------------------------------------------------------------------------
// Circle. Every frequency is a multiple of kOmega, so the path closes after one turn.

constexpr double kOmega = 2.0 * M_PI / 12.0;  // rad/s: one turn in 12 s, 1 degree/frame at 30 fps
constexpr double kTheta0 = -0.75;  // start angle: the first 2 s sweep from the crate to the cabinet
constexpr double kEyeRadiusX = 1.0, kEyeRadiusY = 0.7;  // ellipse of camera centres (m)
constexpr double kEyeHeight = 1.4, kEyeBob = 0.05;      // metres
// The camera looks back across the room centre (heading = path angle + pi), so every view holds
// floor, boxes, walls and often a corner, at 1.5-5 m. The heading turns at the same uniform
// rate as the path angle, plus a small wobble; the pitch swings gently around 15 degrees down.
// (Written as in the first version of this path, so its poses stay bit-identical.)
constexpr double kYawWobble = 0.05;                                               // rad
constexpr double kPitch = 15.0 * M_PI / 180.0, kPitchSwing = 4.0 * M_PI / 180.0;  // rad

// The circle at `seconds` with `extra_heading` (radians) added to its heading; 0 gives the
// circle itself, bit for bit.
SE3 CirclePose(double seconds, double extra_heading) {
  const double phase = kOmega * seconds;
  const double theta = kTheta0 + phase;
  const Eigen::Vector3d eye(kEyeRadiusX * std::cos(theta), kEyeRadiusY * std::sin(theta),
                            kEyeHeight + kEyeBob * std::sin(3.0 * phase));
  const double heading = theta + M_PI + kYawWobble * std::sin(2.0 * phase) + extra_heading;
  const double pitch = -(kPitch + kPitchSwing * std::sin(phase + 1.0));
  return LookAlong(eye, heading, pitch);
}

// ---------------------------------------------------------------------------------------------
// Head turns: yaw swings on top of the circle. A swing of amplitude A at angular frequency w
// turns the head at up to A * w = 99.5 degrees/s; with the circle's ~30 degrees/s in the same
// direction the yaw rate peaks near 130 degrees/s. 5 * kOmega keeps the path periodic in 12 s
// once the swings are eased in.

constexpr double kSwingAmplitude = 38.0 * kDegree;
constexpr double kSwingOmega = 5.0 * kOmega;  // one left-right swing every 2.4 s
constexpr double kSwingEaseIn = 1.0;          // s: the first frames see the swings grow

SE3 HeadTurnsPose(double seconds) {
  const double swing =
      kSwingAmplitude * SmoothStep(seconds / kSwingEaseIn) * std::sin(kSwingOmega * seconds);
  return CirclePose(seconds, swing);
}

// ---------------------------------------------------------------------------------------------
// Walk out. Three stages, joined with zero velocity so the path is smooth:
//   - stand at the -x end, looking at the -x wall and the cabinet, the head swaying a little;
//   - walk towards +x while turning 180 degrees through the -y side (peak ~84 degrees/s and
//     0.6 m/s);
//   - look around the +x half: the +x wall, the table-height box, the floor before them.
// Eye positions keep > 0.6 m from every box and > 2 m from the walls.

constexpr double kStandEnd = 1.5;                                            // s
constexpr double kTurnEnd = 5.5;                                             // s
constexpr double kStandPitch = 15.0 * kDegree, kLookPitch = 20.0 * kDegree;  // down

Eigen::Vector3d StandEye() { return {-0.7, -0.3, 1.45}; }
Eigen::Vector3d ArriveEye() { return {0.5, 0.1, 1.45}; }

SE3 WalkOutPose(double seconds) {
  const double t = std::max(seconds, 0.0);
  if (t < kStandEnd) {
    // sin(2a) sin(a) over a in [0, pi]: a left-right sway that starts and ends at rest.
    const double a = M_PI * t / kStandEnd;
    const double sway = std::sin(2.0 * a) * std::sin(a);
    const Eigen::Vector3d eye = StandEye() + Eigen::Vector3d(0.0, 0.06 * sway, 0.0);
    return LookAlong(eye, M_PI + 0.15 * sway, -kStandPitch);
  }
  if (t < kTurnEnd) {
    const double s = SmootherStep((t - kStandEnd) / (kTurnEnd - kStandEnd));
    const Eigen::Vector3d eye = StandEye() + s * (ArriveEye() - StandEye());
    return LookAlong(eye, M_PI + M_PI * s, -(kStandPitch + s * (kLookPitch - kStandPitch)));
  }
  // Looking around, eased in over 1.5 s so the turn's end is at rest.
  const double tau = t - kTurnEnd;
  const double ease = SmoothStep(tau / 1.5);
  auto wave = [tau](double period) { return std::sin(2.0 * M_PI * tau / period); };
  const Eigen::Vector3d eye =
      ArriveEye() + ease * Eigen::Vector3d(0.12 * wave(5.0), 0.4 * wave(9.0), 0.03 * wave(3.0));
  const double heading = 2.0 * M_PI + ease * 0.35 * wave(7.0);
  const double pitch = -(kLookPitch + ease * 4.0 * kDegree * wave(4.0));
  return LookAlong(eye, heading, pitch);
}

// ---------------------------------------------------------------------------------------------
// Figure eight: eye = (X sin(phi), Y sin(2 phi)) with phi = 2 pi t / period, heading along the
// velocity (X cos(phi), 2 Y cos(2 phi)), which never vanishes, so the heading is smooth. The
// eye stays > 0.6 m from the cabinet (the only box as tall as the eye) and > 1.5 m from the
// walls.

constexpr double kEightPeriod = 20.0;                   // s
constexpr double kEightHalfX = 1.5, kEightHalfY = 0.8;  // m

SE3 EightPose(double seconds, double period, double half_x, double half_y) {
  const double phi = 2.0 * M_PI * seconds / period;
  const Eigen::Vector3d eye(half_x * std::sin(phi), half_y * std::sin(2.0 * phi),
                            kEyeHeight + 0.03 * std::sin(3.0 * phi));
  const double heading = std::atan2(2.0 * half_y * std::cos(2.0 * phi), half_x * std::cos(phi));
  const double pitch = -(kPitch + 3.0 * kDegree * std::sin(phi));
  return LookAlong(eye, heading, pitch);
}

// Through two rooms: the doorway (|y| <= 0.8 m) is crossed at |y| < 0.06 m within the
// partition's 10 cm; the eye stays > 0.6 m from every box as tall as it and > 1.4 m from the
// walls.
constexpr double kTwoRoomPeriod = 30.0;                       // s
constexpr double kTwoRoomHalfX = 3.6, kTwoRoomHalfY = 1.0;  // m

}  // namespace

const char* SyntheticPathName(SyntheticPath path) {
  switch (path) {
    case SyntheticPath::kCircle: return "circle";
    case SyntheticPath::kHeadTurns: return "head-turns";
    case SyntheticPath::kWalkOut: return "walk-out";
    case SyntheticPath::kFigureEight: return "figure-eight";
    case SyntheticPath::kTwoRoomEight: return "two-room-eight";
  }
  return "unknown";
}

absl::StatusOr<SyntheticPath> ParseSyntheticPath(std::string_view name) {
  for (SyntheticPath path : {SyntheticPath::kCircle, SyntheticPath::kHeadTurns,
                            SyntheticPath::kWalkOut, SyntheticPath::kFigureEight,
                            SyntheticPath::kTwoRoomEight}) {
    if (name == SyntheticPathName(path)) return path;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unknown synthetic path \"", std::string(name),
                   "\": expected circle, head-turns, walk-out, figure-eight or two-room-eight"));
}

SyntheticSceneKind SyntheticPathScene(SyntheticPath path) {
  return path == SyntheticPath::kTwoRoomEight ? SyntheticSceneKind::kTwoRooms
                                              : SyntheticSceneKind::kRoom;
}

SE3 SyntheticPathPose(SyntheticPath path, double seconds) {
  switch (path) {
    case SyntheticPath::kHeadTurns: return HeadTurnsPose(seconds);
    case SyntheticPath::kWalkOut: return WalkOutPose(seconds);
    case SyntheticPath::kFigureEight:
      return EightPose(seconds, kEightPeriod, kEightHalfX, kEightHalfY);
    case SyntheticPath::kTwoRoomEight:
      return EightPose(seconds, kTwoRoomPeriod, kTwoRoomHalfX, kTwoRoomHalfY);
    case SyntheticPath::kCircle: break;
  }
  return CirclePose(seconds, 0.0);
}

SE3 SyntheticCameraPoseAtTime(double seconds) { return CirclePose(seconds, 0.0); }

}  // namespace plx

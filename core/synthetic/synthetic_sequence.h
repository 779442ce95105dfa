// Procedural RGB-D sequences of the synthetic room (core/synthetic/synthetic_scene.h) with exact
// ground-truth poses along one of the camera paths of core/synthetic/synthetic_path.h; by
// default a camera circling the room centre at head height (an ellipse of 1 m x 0.7 m),
// looking back across the centre and ~15 degrees down at floor, boxes and walls.
// Optional structured-light-like depth noise and clustered depth holes. Used by tests and
// benchmarks that need a sequence with known geometry and poses.
#pragma once

#include <cstdint>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/synthetic/synthetic_path.h"

namespace plx {

inline constexpr char kSyntheticSequenceName[] = "synthetic_room";

struct SyntheticOptions {
  int width = 320;
  int height = 240;
  // Pinhole intrinsics; 0 means "derive from the image size": fx = fy = 0.85 * width (a
  // horizontal field of view of 61 degrees), cx = width / 2, cy = height / 2.
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  int num_frames = 60;
  double fps = 30.0;
  // The camera path; the default circle gives the same sequence as before paths existed.
  SyntheticPath path = SyntheticPath::kCircle;
  // Standard deviation of the depth noise at 1 m (metres); it grows with z^2 like the
  // disparity error of a structured-light sensor.
  double depth_noise = 0.0;
  // Fraction of depth pixels dropped (set to 0): some at depth discontinuities, the rest in
  // small elliptical blobs, like the holes of a real sensor.
  double hole_fraction = 0.0;
  uint64_t seed = 7;
  // Sensor units per metre reported in the calibration (TUM's 5000); depth stays float metres.
  double depth_scale = 5000.0;
};

// InvalidArgument unless sizes, focal lengths, fps and depth_scale are positive and finite,
// num_frames >= 1, depth_noise >= 0, hole_fraction in [0, 1) and path is a SyntheticPath.
absl::Status ValidateSyntheticOptions(const SyntheticOptions& options);

// The calibration of the generated frames, with the defaults of `options` resolved.
CameraCalibration SyntheticCalibration(const SyntheticOptions& options);

// SyntheticCameraPoseAtTime(seconds) (synthetic_path.h) is the default circle: smooth and
// periodic (one turn every 12 s), about 30 degrees of yaw and 0.35-0.5 m of travel per second,
// i.e. ~1 degree and 1.2-1.7 cm per frame at 30 fps.

// Ground-truth world_T_camera of frame `frame_index` (at frame_index / options.fps seconds) on
// options.path; options.fps must be valid.
SE3 SyntheticCameraPose(const SyntheticOptions& options, int frame_index);

// Renders the sequence "synthetic_room": frame i at i / fps seconds, every frame with its
// ground truth, colour anti-aliased with 2x2 supersampling. Noise and holes come from a
// generator seeded by (seed, frame index), so output does not depend on threading.
absl::StatusOr<InMemoryDataset> GenerateSyntheticSequence(const SyntheticOptions& options);

}  // namespace plx

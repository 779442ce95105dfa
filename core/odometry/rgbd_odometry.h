// Map-free RGB-D odometry: the pose of a frame relative to the frame before it, from their
// images alone, coarse to fine (DVO-style dense alignment). It needs no map, so it keeps a pose
// where the map cannot render yet (unmapped space) and across motions too large for the map
// tracker's basin (fast head turns): the SLAM front-end gives its estimate to the map tracker
// as the starting point (docs/SLAM.md, "Front-end").
//
// Every point of the current frame with valid depth (a subset per level, half of it where the
// intensity gradient is strongest) is moved into the reference camera by reference_T_current
// and compared there twice: photometrically (reference intensity minus its own) and
// geometrically (reference depth minus its depth in the reference camera), each scaled by a
// robust estimate of its noise (the median absolute residual; depth also by the sensor's noise
// at that depth) and weighted by Huber. So neither term needs a hand-set balance, and colour
// that is not registered to depth (a few pixels off) mostly loses weight rather than biasing
// the pose. Gauss-Newton per level; the coarse levels give the basin, the finest kept level
// (320 px wide by default) the accuracy.
//
// It runs on the host: on the coarse levels a frame is a few thousand points per iteration
// (milliseconds on one core); the per-point term is PLX_HD (core/odometry/odometry_terms.h) so it
// can move to a backend kernel when that pays.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"
#include "core/math/depth_noise.h"
#include "core/odometry/odometry_pyramid.h"

namespace plx {

struct OdometryOptions {
  int max_points = 4000;           // per level
  int iterations_per_level = 12;
  double converged_step = 1e-5;    // |xi| (metres and radians) that ends a level
  float huber_k = 1.345f;          // in robust noise units
  DepthNoiseModel depth_noise;
  float depth_sigma_floor = 0.002f;      // metres
  float intensity_sigma_floor = 0.004f;  // about one 8-bit grey level
  // Quality gates for `ok` (the estimate is trusted).
  double min_valid_fraction = 0.3;       // points landing inside the reference image
  double min_depth_inlier_fraction = 0.5;
  int min_points = 100;
  double max_translation_m = 0.30;       // between consecutive frames
  double max_rotation_rad = 0.60;        // ~34 degrees: 1000 deg/s at 30 fps
};

absl::Status ValidateOdometryOptions(const OdometryOptions& options);

struct OdometryResult {
  SE3 reference_T_current;
  bool ok = false;
  std::string reason;               // why not ok
  int points = 0;                   // used at the finest level
  double valid_fraction = 0.0;      // of them, landing inside the reference
  double depth_inlier_fraction = 0.0;  // of those with depth there, within 3 sigma (or 1 %)
  double intensity_rmse = 0.0;      // at the finest level, inliers' raw residuals
  double depth_rmse_m = 0.0;
  int iterations = 0;               // all levels
  // Smallest eigenvalue of the finest level's normal equations per point, in normalised units:
  // near 0 when some motion is not observable (a blank wall seen head-on).
  double min_information = 0.0;
};

// Aligns `current` to `reference` (pyramids of frames with the same intrinsics and options)
// from `initial` (e.g. the constant-velocity guess). InvalidArgument when the pyramids do not
// match; a frame that cannot be aligned is a result with ok = false and a reason.
absl::StatusOr<OdometryResult> EstimateOdometry(const OdometryPyramid& reference,
                                                const OdometryPyramid& current,
                                                const SE3& initial,
                                                const OdometryOptions& options);

}  // namespace plx

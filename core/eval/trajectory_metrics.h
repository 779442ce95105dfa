// Trajectory accuracy as evo (github.com/MichaelGrupp/evo) computes it, so numbers reported by
// plenox compare with the SLAM papers that use `evo_ape` / `evo_rpe` (the WACV 2024 reference
// scores itself with evo: ATE without alignment, RPE with delta = 1 m).
//
// Pipeline (EvaluateTrajectory):
//   1. Association by timestamp (evo: core/sync.py, associate_trajectories +
//      matching_time_indices): every estimated pose takes the ground-truth pose with the
//      nearest timestamp if |dt| <= max_dt. Unmatched poses drop out of everything below.
//   2. Optional alignment of the estimate onto the ground truth (evo_ape -a / -as: Umeyama on
//      the matched positions, core/geometry.py umeyama_alignment, applied with
//      PosePath3D.align).
//   3. ATE = evo APE, translation part: ||t_est_aligned - t_gt|| per matched pose; RMSE, mean,
//      median, max, ... (core/metrics.py APE, PE.get_statistic).
//   4. RPE = evo RPE, translation part and rotation angle in degrees, delta in metres,
//      consecutive pairs (core/metrics.py RPE.process_data, core/filters.py
//      filter_pairs_by_path with all_pairs=False). Computed on the aligned estimate, as evo_rpe
//      does when given the same alignment flag (only Sim(3) changes RPE: it scales the
//      estimate's relative translations).
// Where this departs from evo, the comment at the function says so.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"

namespace plx {

// ---------------------------------------------------------------------------------------------
// Association

// Pairs (estimate index, ground-truth index), sorted by estimate index. For each estimated stamp
// the ground-truth stamp nearest to it (ties: the earlier one) is taken when |difference| <=
// max_dt, as evo's matching_time_indices does. Unlike evo, each ground-truth pose is used at
// most once: when several estimated stamps pick the same one, the closest keeps it (ties: the
// earlier estimate) and the others stay unmatched. (evo matches the shorter trajectory onto the
// longer one and would let two poses share a partner; with an estimate sparser than the
// ground truth, the usual case, both rules give the same pairs.) Neither input needs to be
// sorted. evo's default max_dt is 0.01 s; EvaluateTrajectory defaults to 0.02 s, which also
// accepts TUM's 30 Hz camera stamps against its 100 Hz ground truth when the two clocks are
// offset by up to 20 ms.
std::vector<std::pair<int, int>> AssociateEstimateToGroundTruth(
    const std::vector<double>& estimate_times, const std::vector<double>& ground_truth_times,
    double max_dt);

// ---------------------------------------------------------------------------------------------
// Alignment

enum class TrajectoryAlignment {
  kNone,  // compare as given (the reference paper's protocol: frame 0 starts at ground truth)
  kSE3,   // rotation + translation (evo -a); the right choice for RGB-D, where depth fixes scale
  kSim3,  // rotation + translation + scale (evo -as), for monocular-style estimates
};

// "none", "se3", "sim3".
absl::StatusOr<TrajectoryAlignment> ParseTrajectoryAlignment(const std::string& name);
const char* TrajectoryAlignmentName(TrajectoryAlignment alignment);

// x -> scale * rotation * x + translation.
struct Similarity3 {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const {
    return scale * (rotation * x) + translation;
  }
  // A world_T_camera pose moved into the target frame: the camera centre maps like a point,
  // the orientation is rotated; the pose stays rigid (scale only moves the centre).
  SE3 operator*(const SE3& pose) const;
};

// Least-squares similarity (Umeyama 1991, "Least-squares estimation of transformation
// parameters between two point patterns") taking `source` (column i) onto `target`
// (column i): minimises sum ||target_i - (s R source_i + t)||^2 over rotations R (det +1),
// translations t and, with `with_scale`, scales s > 0 (else s = 1). The SVD of the
// cross-covariance can produce a reflection; the sign correction of Umeyama's eq. 39/43 keeps R
// a proper rotation. With all points collinear the rotation about that line is not determined
// (any valid one is returned). Errors: different column counts, no points, non-finite values,
// and (with scale) a source whose points all coincide.
absl::StatusOr<Similarity3> UmeyamaAlignment(const Eigen::Matrix3Xd& source,
                                             const Eigen::Matrix3Xd& target, bool with_scale);

// ---------------------------------------------------------------------------------------------
// Errors

// evo's statistics of one error array (PE.get_statistic): std is the population standard
// deviation (numpy's default), median averages the two middle values of an even count.
// With count == 0 every value is NaN.
struct ErrorStatistics {
  int count = 0;
  double rmse = 0.0;
  double mean = 0.0;
  double median = 0.0;
  double std = 0.0;
  double min = 0.0;
  double max = 0.0;
};
ErrorStatistics ComputeErrorStatistics(std::vector<double> errors);

// Which trajectory's travelled path picks the RPE pairs.
enum class RpePathSource {
  kEstimate,     // evo: RPE.process_data passes traj_est to id_pairs_from_delta (the default)
  kGroundTruth,  // the path of the reference; independent of the estimate's drift
};
const char* RpePathSourceName(RpePathSource source);
// "est", "gt".
absl::StatusOr<RpePathSource> ParseRpePathSource(const std::string& name);

// Index pairs (i, j) of `poses` whose travelled path is about `delta` metres apart, evo's
// consecutive-pairs rule (filter_pairs_by_path, all_pairs=False): walk the poses from the first,
// adding the distance to the previous pose to a running path length; each time the running
// length reaches `delta` (>=), record that index and reset the running length to zero (the
// overshoot is dropped, not carried). The pairs are the consecutive recorded indices:
// (k1, k2), (k2, k3), ... Note that the first pair starts at the first recorded index, not at
// pose 0, so a trajectory needs at least 2 * delta of path for one pair; evo's tolerance
// (delta * rel_tol) only applies to all_pairs mode and so plays no part. Empty when there are
// fewer than two crossings.
std::vector<std::pair<int, int>> RpePairsByPath(const std::vector<SE3>& poses, double delta);

// Total path length sum ||t_{k+1} - t_k||.
double PathLength(const std::vector<SE3>& poses);

// Rotation angle of `pose` in radians, in [0, pi] (2 atan2(|v|, |w|): accurate near zero,
// where 2 acos(w) loses half the digits).
double RotationAngle(const SE3& pose);

struct AteResult {
  ErrorStatistics translation_m;  // per matched pose, after alignment
  Similarity3 alignment;          // applied to the estimate (identity for kNone)
};

// ATE of matched pose lists (estimate[k] belongs with ground_truth[k]). Alignment kSE3/kSim3
// needs at least 3 poses (evo runs with fewer, but an alignment fitted to 1 or 2 positions
// makes the error meaningless); kSim3 also needs the positions not all equal.
absl::StatusOr<AteResult> ComputeAte(const std::vector<SE3>& estimate,
                                     const std::vector<SE3>& ground_truth,
                                     TrajectoryAlignment alignment);

struct RpeResult {
  // Per pair E = (gt_i^-1 gt_j)^-1 (est_i^-1 est_j) (evo's rpe_base: relative_se3(Q_rel, P_rel)):
  ErrorStatistics translation_m;     // ||translation(E)||
  ErrorStatistics rotation_deg;      // rotation angle of E, degrees
  std::vector<std::pair<int, int>> pairs;
  double path_length_m = 0.0;        // of the trajectory the pairs were picked on
};

// RPE of matched pose lists (same length), pairs picked by RpePairsByPath on the trajectory
// `path_source` names. No pairs is not an error (evo raises one): the statistics are then NaN
// with count 0 and `pairs` is empty, so callers can report "shorter than 2 * delta".
absl::StatusOr<RpeResult> ComputeRpe(const std::vector<SE3>& estimate,
                                     const std::vector<SE3>& ground_truth, double delta_m,
                                     RpePathSource path_source = RpePathSource::kEstimate);

// ---------------------------------------------------------------------------------------------
// Everything at once

struct TrajectoryEvalOptions {
  double max_dt = 0.02;  // seconds; evo's --t_max_diff default is 0.01
  TrajectoryAlignment alignment = TrajectoryAlignment::kNone;
  double rpe_delta_m = 1.0;
  RpePathSource rpe_path = RpePathSource::kEstimate;
};

struct TrajectoryEvalResult {
  int estimate_poses = 0;
  int ground_truth_poses = 0;
  int matched = 0;  // estimated poses with a ground-truth partner
  TrajectoryAlignment alignment = TrajectoryAlignment::kNone;
  AteResult ate;
  RpeResult rpe;  // rpe.pairs.empty(): the matched trajectory is too short for delta
};

// Associates, aligns, and computes ATE and RPE. Errors: an empty trajectory, max_dt negative or
// not finite, delta not positive, no pose matched within max_dt (the message gives both time
// ranges, since the usual cause is a clock offset or a file in the wrong units), and the
// alignment errors of ComputeAte.
absl::StatusOr<TrajectoryEvalResult> EvaluateTrajectory(
    const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& ground_truth,
    const TrajectoryEvalOptions& options = {});

}  // namespace plx

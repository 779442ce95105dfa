#include "core/eval/trajectory_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/SVD>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRadToDeg = 180.0 / M_PI;

// Below this spread (m^2, mean squared distance to the centroid) the source positions are one
// point and a scale cannot be estimated.
constexpr double kMinSourceVariance = 1e-18;

// Alignment needs this many matched poses (see ComputeAte).
constexpr int kMinPosesToAlign = 3;

Eigen::Matrix3Xd Positions(const std::vector<SE3>& poses) {
  Eigen::Matrix3Xd m(3, static_cast<Eigen::Index>(poses.size()));
  for (size_t k = 0; k < poses.size(); ++k) {
    m.col(static_cast<Eigen::Index>(k)) = poses[k].translation();
  }
  return m;
}

std::string TimeRange(const std::vector<StampedPose>& poses) {
  const auto [first, last] = std::minmax_element(
      poses.begin(), poses.end(),
      [](const StampedPose& a, const StampedPose& b) { return a.timestamp < b.timestamp; });
  return absl::StrFormat("[%.6f, %.6f] s (%d poses)", first->timestamp, last->timestamp,
                         poses.size());
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Association

std::vector<std::pair<int, int>> AssociateEstimateToGroundTruth(
    const std::vector<double>& estimate_times, const std::vector<double>& ground_truth_times,
    double max_dt) {
  // Ground truth in time order (stable, so equal stamps keep file order and the first wins, like
  // numpy's argmin).
  std::vector<int> order(ground_truth_times.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return ground_truth_times[a] < ground_truth_times[b];
  });
  std::vector<double> sorted(order.size());
  for (size_t k = 0; k < order.size(); ++k) sorted[k] = ground_truth_times[order[k]];

  // claim[g] = (|dt|, estimate index) of the estimate currently holding ground-truth pose g.
  constexpr int kFree = -1;
  std::vector<std::pair<double, int>> claim(ground_truth_times.size(), {0.0, kFree});
  for (int e = 0; e < static_cast<int>(estimate_times.size()); ++e) {
    const double t = estimate_times[e];
    if (sorted.empty() || !std::isfinite(t)) continue;
    // The nearest stamp is the first one >= t or the one before it; on a tie the earlier wins.
    const auto it = std::lower_bound(sorted.begin(), sorted.end(), t);
    size_t best = static_cast<size_t>(it - sorted.begin());
    if (best == sorted.size() || (best > 0 && t - sorted[best - 1] <= sorted[best] - t)) {
      // Step back to the first of a run of equal stamps as well.
      best = static_cast<size_t>(
          std::lower_bound(sorted.begin(), sorted.end(), sorted[best - 1]) - sorted.begin());
    }
    const double dt = std::abs(sorted[best] - t);
    if (!(dt <= max_dt)) continue;
    std::pair<double, int>& holder = claim[order[best]];
    // Strictly closer takes the pose over; on a tie the estimate that came first keeps it.
    if (holder.second == kFree || dt < holder.first) holder = {dt, e};
  }

  std::vector<std::pair<int, int>> pairs;
  for (int g = 0; g < static_cast<int>(claim.size()); ++g) {
    if (claim[g].second != kFree) pairs.emplace_back(claim[g].second, g);
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

// ---------------------------------------------------------------------------------------------
// Alignment

absl::StatusOr<TrajectoryAlignment> ParseTrajectoryAlignment(const std::string& name) {
  if (name == "none") return TrajectoryAlignment::kNone;
  if (name == "se3") return TrajectoryAlignment::kSE3;
  if (name == "sim3") return TrajectoryAlignment::kSim3;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown alignment \"", name, "\" (expected none, se3 or sim3)"));
}

const char* TrajectoryAlignmentName(TrajectoryAlignment alignment) {
  switch (alignment) {
    case TrajectoryAlignment::kNone: return "none";
    case TrajectoryAlignment::kSE3: return "se3";
    case TrajectoryAlignment::kSim3: return "sim3";
  }
  return "?";
}

SE3 Similarity3::operator*(const SE3& pose) const {
  return SE3(Eigen::Matrix3d(rotation * pose.rotation_matrix()), (*this) * pose.translation());
}

absl::StatusOr<Similarity3> UmeyamaAlignment(const Eigen::Matrix3Xd& source,
                                             const Eigen::Matrix3Xd& target, bool with_scale) {
  const Eigen::Index n = source.cols();
  if (target.cols() != n) {
    return absl::InvalidArgumentError(absl::StrCat(
        "Umeyama alignment: ", n, " source points but ", target.cols(), " target points"));
  }
  if (n == 0) return absl::InvalidArgumentError("Umeyama alignment: no points");
  if (!source.allFinite() || !target.allFinite()) {
    return absl::InvalidArgumentError("Umeyama alignment: the points must be finite");
  }

  // Centroids (Umeyama eq. 34, 35) and the source variance (eq. 36).
  const Eigen::Vector3d mean_source = source.rowwise().mean();
  const Eigen::Vector3d mean_target = target.rowwise().mean();
  const Eigen::Matrix3Xd centered_source = source.colwise() - mean_source;
  const Eigen::Matrix3Xd centered_target = target.colwise() - mean_target;
  const double source_variance = centered_source.squaredNorm() / static_cast<double>(n);

  // Cross-covariance (eq. 38) and its SVD, U D V^T with D sorted in decreasing order.
  const Eigen::Matrix3d covariance =
      centered_target * centered_source.transpose() / static_cast<double>(n);
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d& u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();

  // U V^T is the best orthogonal matrix, but it is a reflection when det(U) det(V) < 0 (noisy or
  // mirrored points; with coplanar points the sign of the null direction is arbitrary). Flipping
  // the axis of the smallest singular value gives the best proper rotation (eq. 39 / 43).
  Eigen::Vector3d s = Eigen::Vector3d::Ones();
  if (u.determinant() * v.determinant() < 0.0) s.z() = -1.0;

  Similarity3 result;
  result.rotation = u * s.asDiagonal() * v.transpose();  // eq. 40
  if (with_scale) {
    if (source_variance < kMinSourceVariance) {
      return absl::FailedPreconditionError(
          "Umeyama alignment: all source points coincide, the scale is undetermined");
    }
    result.scale = svd.singularValues().dot(s) / source_variance;  // eq. 42: tr(DS) / sigma^2
  }
  result.translation = mean_target - result.scale * (result.rotation * mean_source);  // eq. 41
  return result;
}

// ---------------------------------------------------------------------------------------------
// Errors

ErrorStatistics ComputeErrorStatistics(std::vector<double> errors) {
  ErrorStatistics stats;
  stats.count = static_cast<int>(errors.size());
  if (errors.empty()) {
    stats.rmse = stats.mean = stats.median = stats.std = stats.min = stats.max = kNaN;
    return stats;
  }
  const double n = static_cast<double>(errors.size());
  double sum = 0.0, sum_squares = 0.0;
  for (double e : errors) {
    sum += e;
    sum_squares += e * e;
  }
  stats.mean = sum / n;
  stats.rmse = std::sqrt(sum_squares / n);
  double deviation_squares = 0.0;
  for (double e : errors) deviation_squares += (e - stats.mean) * (e - stats.mean);
  stats.std = std::sqrt(deviation_squares / n);
  std::sort(errors.begin(), errors.end());
  stats.min = errors.front();
  stats.max = errors.back();
  const size_t half = errors.size() / 2;
  stats.median = errors.size() % 2 == 1 ? errors[half] : 0.5 * (errors[half - 1] + errors[half]);
  return stats;
}

const char* RpePathSourceName(RpePathSource source) {
  return source == RpePathSource::kEstimate ? "est" : "gt";
}

absl::StatusOr<RpePathSource> ParseRpePathSource(const std::string& name) {
  if (name == "est") return RpePathSource::kEstimate;
  if (name == "gt") return RpePathSource::kGroundTruth;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown RPE path source \"", name, "\" (expected est or gt)"));
}

std::vector<std::pair<int, int>> RpePairsByPath(const std::vector<SE3>& poses, double delta) {
  // evo filters.py, filter_pairs_by_path(all_pairs=False), step by step: the running path starts
  // at 0 with "previous" = pose 0 (so pose 0 adds nothing), every pose adds its distance to the
  // previous one, and an index is recorded, with the running path reset to 0, whenever the
  // running path is >= delta.
  std::vector<int> crossings;
  double running = 0.0;
  for (size_t k = 0; k < poses.size(); ++k) {
    if (k > 0) running += (poses[k].translation() - poses[k - 1].translation()).norm();
    if (running >= delta) {
      crossings.push_back(static_cast<int>(k));
      running = 0.0;
    }
  }
  std::vector<std::pair<int, int>> pairs;
  for (size_t k = 1; k < crossings.size(); ++k) pairs.emplace_back(crossings[k - 1], crossings[k]);
  return pairs;
}

double PathLength(const std::vector<SE3>& poses) {
  double length = 0.0;
  for (size_t k = 1; k < poses.size(); ++k) {
    length += (poses[k].translation() - poses[k - 1].translation()).norm();
  }
  return length;
}

double RotationAngle(const SE3& pose) {
  const Eigen::Quaterniond& q = pose.rotation();
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

absl::StatusOr<AteResult> ComputeAte(const std::vector<SE3>& estimate,
                                     const std::vector<SE3>& ground_truth,
                                     TrajectoryAlignment alignment) {
  if (estimate.size() != ground_truth.size()) {
    return absl::InvalidArgumentError(absl::StrCat("ATE: ", estimate.size(),
                                                   " estimated poses but ", ground_truth.size(),
                                                   " ground-truth poses"));
  }
  if (estimate.empty()) return absl::InvalidArgumentError("ATE: no poses");
  AteResult result;
  if (alignment != TrajectoryAlignment::kNone) {
    if (static_cast<int>(estimate.size()) < kMinPosesToAlign) {
      return absl::FailedPreconditionError(
          absl::StrCat("ATE: ", TrajectoryAlignmentName(alignment), " alignment needs at least ",
                       kMinPosesToAlign, " matched poses, got ", estimate.size()));
    }
    PLX_ASSIGN_OR_RETURN(result.alignment,
                         UmeyamaAlignment(Positions(estimate), Positions(ground_truth),
                                          alignment == TrajectoryAlignment::kSim3));
  }
  std::vector<double> errors(estimate.size());
  for (size_t k = 0; k < estimate.size(); ++k) {
    const Eigen::Vector3d aligned = alignment == TrajectoryAlignment::kNone
                                        ? estimate[k].translation()
                                        : result.alignment * estimate[k].translation();
    errors[k] = (aligned - ground_truth[k].translation()).norm();
  }
  result.translation_m = ComputeErrorStatistics(std::move(errors));
  return result;
}

absl::StatusOr<RpeResult> ComputeRpe(const std::vector<SE3>& estimate,
                                     const std::vector<SE3>& ground_truth, double delta_m,
                                     RpePathSource path_source) {
  if (estimate.size() != ground_truth.size()) {
    return absl::InvalidArgumentError(absl::StrCat("RPE: ", estimate.size(),
                                                   " estimated poses but ", ground_truth.size(),
                                                   " ground-truth poses"));
  }
  if (!(delta_m > 0.0) || !std::isfinite(delta_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("RPE: delta must be a positive number of metres, got ", delta_m));
  }
  const std::vector<SE3>& path =
      path_source == RpePathSource::kEstimate ? estimate : ground_truth;
  RpeResult result;
  result.pairs = RpePairsByPath(path, delta_m);
  result.path_length_m = PathLength(path);
  std::vector<double> translation_errors, rotation_errors;
  translation_errors.reserve(result.pairs.size());
  rotation_errors.reserve(result.pairs.size());
  for (const auto& [i, j] : result.pairs) {
    const SE3 ground_truth_motion = ground_truth[i].Inverse() * ground_truth[j];
    const SE3 estimated_motion = estimate[i].Inverse() * estimate[j];
    const SE3 error = ground_truth_motion.Inverse() * estimated_motion;
    translation_errors.push_back(error.translation().norm());
    rotation_errors.push_back(RotationAngle(error) * kRadToDeg);
  }
  result.translation_m = ComputeErrorStatistics(std::move(translation_errors));
  result.rotation_deg = ComputeErrorStatistics(std::move(rotation_errors));
  return result;
}

// ---------------------------------------------------------------------------------------------
// Everything at once

absl::StatusOr<TrajectoryEvalResult> EvaluateTrajectory(
    const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& ground_truth,
    const TrajectoryEvalOptions& options) {
  if (!(options.max_dt >= 0.0) || !std::isfinite(options.max_dt)) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_dt must be a finite number of seconds >= 0, got ", options.max_dt));
  }
  if (!(options.rpe_delta_m > 0.0) || !std::isfinite(options.rpe_delta_m)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the RPE delta must be a positive number of metres, got ", options.rpe_delta_m));
  }
  if (estimate.empty()) return absl::InvalidArgumentError("the estimated trajectory is empty");
  if (ground_truth.empty()) return absl::InvalidArgumentError("the ground truth is empty");

  std::vector<double> estimate_times, ground_truth_times;
  estimate_times.reserve(estimate.size());
  ground_truth_times.reserve(ground_truth.size());
  for (const StampedPose& p : estimate) estimate_times.push_back(p.timestamp);
  for (const StampedPose& p : ground_truth) ground_truth_times.push_back(p.timestamp);
  const std::vector<std::pair<int, int>> matches =
      AssociateEstimateToGroundTruth(estimate_times, ground_truth_times, options.max_dt);
  if (matches.empty()) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "no estimated pose has a ground-truth pose within %g s: the estimate spans %s, the "
        "ground truth %s",
        options.max_dt, TimeRange(estimate), TimeRange(ground_truth)));
  }

  TrajectoryEvalResult result;
  result.estimate_poses = static_cast<int>(estimate.size());
  result.ground_truth_poses = static_cast<int>(ground_truth.size());
  result.matched = static_cast<int>(matches.size());
  result.alignment = options.alignment;

  std::vector<SE3> matched_estimate, matched_ground_truth;
  matched_estimate.reserve(matches.size());
  matched_ground_truth.reserve(matches.size());
  for (const auto& [e, g] : matches) {
    matched_estimate.push_back(estimate[e].pose);
    matched_ground_truth.push_back(ground_truth[g].pose);
  }
  PLX_ASSIGN_OR_RETURN(result.ate,
                       ComputeAte(matched_estimate, matched_ground_truth, options.alignment));
  // RPE on the aligned estimate, like evo_rpe with the same -a / -as flag. A rigid alignment
  // leaves every relative pose unchanged; Sim(3) scales the relative translations.
  if (options.alignment != TrajectoryAlignment::kNone) {
    for (SE3& pose : matched_estimate) pose = result.ate.alignment * pose;
  }
  PLX_ASSIGN_OR_RETURN(result.rpe, ComputeRpe(matched_estimate, matched_ground_truth,
                                              options.rpe_delta_m, options.rpe_path));
  return result;
}

}  // namespace plx

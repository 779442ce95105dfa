#include "core/odometry/rgbd_odometry.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Dense>

#include "absl/strings/str_format.h"
#include "core/geometry/kernel_camera.h"
#include "core/odometry/odometry_terms.h"

namespace plx {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// The median absolute deviation times this estimates a Gaussian's sigma.
constexpr double kMadToSigma = 1.4826;

struct LevelPoints {
  std::vector<Vec3f> q;           // in the current camera
  std::vector<float> intensity;
};

OdometryLevelView ViewOf(const OdometryLevel& l) {
  return OdometryLevelView{l.width,           l.height,          l.fx,
                           l.fy,              l.cx,              l.cy,
                           l.intensity.data(), l.intensity_du.data(), l.intensity_dv.data(),
                           l.depth.data(),     l.depth_du.data(),     l.depth_dv.data(),
                           l.depth_smooth.data()};
}

// Every pixel with depth when they are few; else half the budget where the intensity gradient
// is strongest (they carry the photometric term) and half spread evenly over the rest (they
// carry the geometric one on textureless surfaces).
LevelPoints SelectPoints(const OdometryLevel& level, int max_points) {
  std::vector<int> candidates;
  for (int i = 0; i < level.width * level.height; ++i) {
    if (level.depth[i] > 0.0f) candidates.push_back(i);
  }
  std::vector<int> chosen;
  if (static_cast<int>(candidates.size()) <= max_points) {
    chosen = candidates;
  } else {
    auto strength = [&](int i) {
      return level.intensity_du[i] * level.intensity_du[i] +
             level.intensity_dv[i] * level.intensity_dv[i];
    };
    const int strong = max_points / 2;
    std::nth_element(candidates.begin(), candidates.begin() + strong, candidates.end(),
                     [&](int a, int b) { return strength(a) > strength(b) ||
                                                (strength(a) == strength(b) && a < b); });
    chosen.assign(candidates.begin(), candidates.begin() + strong);
    const int64_t rest = static_cast<int64_t>(candidates.size()) - strong;
    const int spread = max_points - strong;
    for (int j = 0; j < spread; ++j) {
      chosen.push_back(candidates[strong + static_cast<int64_t>(j) * rest / spread]);
    }
  }
  LevelPoints points;
  points.q.reserve(chosen.size());
  points.intensity.reserve(chosen.size());
  for (int i : chosen) {
    const int u = i % level.width, v = i / level.width;
    const float z = level.depth[i];
    points.q.push_back(Vec3f{(u + 0.5f - level.cx) / level.fx * z,
                             (v + 0.5f - level.cy) / level.fy * z, z});
    points.intensity.push_back(level.intensity[i]);
  }
  return points;
}

std::vector<OdometryPointTerm> ComputeTerms(const OdometryLevelView& reference,
                                            const SE3& reference_T_current,
                                            const LevelPoints& points,
                                            const DepthNoiseModel& noise) {
  const RigidTransformf transform = ToKernelTransform(reference_T_current);
  std::vector<OdometryPointTerm> terms(points.q.size());
  for (size_t i = 0; i < points.q.size(); ++i) {
    terms[i] = ComputeOdometryTerm(reference, transform, points.q[i], points.intensity[i], noise);
  }
  return terms;
}

float Median(std::vector<float>* values) {
  if (values->empty()) return 0.0f;
  auto middle = values->begin() + values->size() / 2;
  std::nth_element(values->begin(), middle, values->end());
  return *middle;
}

// Robust noise scales of this pass: intensity in intensity units; depth in units of the
// sensor's noise (so 1 means "as noisy as the sensor").
struct RobustScales {
  float intensity = 0.0f;
  float depth = 1.0f;
};

float DepthSigma(const OdometryPointTerm& t, const OdometryOptions& o) {
  return std::max(t.depth_sigma, o.depth_sigma_floor);
}

RobustScales EstimateScales(const std::vector<OdometryPointTerm>& terms,
                            const OdometryOptions& o) {
  std::vector<float> intensity, depth;
  for (const OdometryPointTerm& t : terms) {
    if (t.has_intensity) intensity.push_back(std::fabs(t.intensity_residual));
    if (t.has_depth) depth.push_back(std::fabs(t.depth_residual) / DepthSigma(t, o));
  }
  RobustScales s;
  s.intensity = std::max(o.intensity_sigma_floor,
                         static_cast<float>(kMadToSigma * Median(&intensity)));
  s.depth = std::max(1.0f, static_cast<float>(kMadToSigma * Median(&depth)));
  return s;
}

float HuberWeight(float scaled_residual, float k) {
  const float a = std::fabs(scaled_residual);
  return a <= k ? 1.0f : k / a;
}

struct NormalEquations {
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  int residuals = 0;
};

NormalEquations Accumulate(const std::vector<OdometryPointTerm>& terms, const RobustScales& s,
                           const OdometryOptions& o) {
  NormalEquations eq;
  auto add = [&](const float* jacobian, float residual, float scale) {
    Vector6d J;
    for (int k = 0; k < 6; ++k) J[k] = jacobian[k] / scale;
    const double e = residual / scale;
    const double w = HuberWeight(static_cast<float>(e), o.huber_k);
    eq.H.noalias() += w * J * J.transpose();
    eq.g.noalias() += w * e * J;
    ++eq.residuals;
  };
  for (const OdometryPointTerm& t : terms) {
    if (t.has_intensity) add(t.intensity_jacobian, t.intensity_residual, s.intensity);
    if (t.has_depth) add(t.depth_jacobian, t.depth_residual, DepthSigma(t, o) * s.depth);
  }
  return eq;
}

bool SameGeometry(const OdometryLevel& a, const OdometryLevel& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy;
}

// The final estimate's quality at the finest level, and the gates.
void Assess(const std::vector<OdometryPointTerm>& terms, const NormalEquations& eq,
            const OdometryOptions& o, OdometryResult* r) {
  int inside = 0, with_depth = 0, depth_inliers = 0;
  double intensity_sq = 0.0, depth_sq = 0.0;
  for (const OdometryPointTerm& t : terms) {
    if (!t.has_intensity) continue;
    ++inside;
    intensity_sq += t.intensity_residual * t.intensity_residual;
    if (!t.has_depth) continue;
    ++with_depth;
    if (std::fabs(t.depth_residual) <= std::max(3.0f * t.depth_sigma, 0.01f)) {
      ++depth_inliers;
      depth_sq += t.depth_residual * t.depth_residual;
    }
  }
  r->points = static_cast<int>(terms.size());
  r->valid_fraction = terms.empty() ? 0.0 : static_cast<double>(inside) / terms.size();
  r->depth_inlier_fraction = with_depth > 0 ? static_cast<double>(depth_inliers) / with_depth : 0;
  r->intensity_rmse = inside > 0 ? std::sqrt(intensity_sq / inside) : 0.0;
  r->depth_rmse_m = depth_inliers > 0 ? std::sqrt(depth_sq / depth_inliers) : 0.0;
  if (eq.residuals > 0) {
    const Eigen::SelfAdjointEigenSolver<Matrix6d> eigen(eq.H / eq.residuals,
                                                       Eigen::EigenvaluesOnly);
    r->min_information = eigen.eigenvalues()[0];
  }
  const double translation = r->reference_T_current.translation().norm();
  const double rotation = Eigen::AngleAxisd(r->reference_T_current.rotation()).angle();
  if (r->points < o.min_points) {
    r->reason = absl::StrFormat("too little depth (%d points)", r->points);
  } else if (r->valid_fraction < o.min_valid_fraction) {
    r->reason = absl::StrFormat("%.0f%% of the points land in the previous frame",
                                100 * r->valid_fraction);
  } else if (with_depth >= o.min_points &&
             r->depth_inlier_fraction < o.min_depth_inlier_fraction) {
    r->reason = absl::StrFormat("%.0f%% of the depth agrees with the previous frame",
                                100 * r->depth_inlier_fraction);
  } else if (!(translation <= o.max_translation_m) || !(rotation <= o.max_rotation_rad)) {
    r->reason = absl::StrFormat("implausible motion (%.2f m, %.0f deg)", translation,
                                rotation * 180.0 / M_PI);
  } else {
    r->ok = true;
  }
}

}  // namespace

absl::Status ValidateOdometryOptions(const OdometryOptions& o) {
  if (o.max_points < 16) return absl::InvalidArgumentError("odometry: max_points < 16");
  if (o.iterations_per_level < 1) {
    return absl::InvalidArgumentError("odometry: iterations_per_level < 1");
  }
  if (!(o.huber_k > 0.0f) || !(o.depth_sigma_floor > 0.0f) || !(o.intensity_sigma_floor > 0.0f)) {
    return absl::InvalidArgumentError("odometry: huber_k and the sigma floors must be > 0");
  }
  if (!(o.min_valid_fraction >= 0.0 && o.min_valid_fraction <= 1.0) ||
      !(o.min_depth_inlier_fraction >= 0.0 && o.min_depth_inlier_fraction <= 1.0)) {
    return absl::InvalidArgumentError("odometry: fractions must be in [0, 1]");
  }
  return absl::OkStatus();
}

absl::StatusOr<OdometryResult> EstimateOdometry(const OdometryPyramid& reference,
                                                const OdometryPyramid& current,
                                                const SE3& initial,
                                                const OdometryOptions& options) {
  if (absl::Status s = ValidateOdometryOptions(options); !s.ok()) return s;
  if (reference.levels.empty() || reference.levels.size() != current.levels.size()) {
    return absl::InvalidArgumentError("odometry: the two pyramids have different levels");
  }
  for (size_t l = 0; l < reference.levels.size(); ++l) {
    if (!SameGeometry(reference.levels[l], current.levels[l])) {
      return absl::InvalidArgumentError("odometry: the two frames have different intrinsics");
    }
  }
  OdometryResult result;
  result.reference_T_current = initial;
  std::vector<OdometryPointTerm> terms;
  NormalEquations eq;
  for (int l = static_cast<int>(current.levels.size()) - 1; l >= 0; --l) {
    const LevelPoints points = SelectPoints(current.levels[l], options.max_points);
    const OdometryLevelView view = ViewOf(reference.levels[l]);
    if (static_cast<int>(points.q.size()) < options.min_points && l > 0) continue;
    for (int it = 0; it < options.iterations_per_level; ++it) {
      terms = ComputeTerms(view, result.reference_T_current, points, options.depth_noise);
      eq = Accumulate(terms, EstimateScales(terms, options), options);
      if (eq.residuals < 6) break;
      const double damping = 1e-6 * std::max(eq.H.trace() / 6.0, 1e-12);
      const Vector6d step =
          (eq.H + damping * Matrix6d::Identity()).ldlt().solve(-eq.g);
      if (!step.allFinite()) break;
      result.reference_T_current = result.reference_T_current * SE3::Exp(step);
      ++result.iterations;
      if (step.norm() < options.converged_step) break;
    }
    if (l == 0) {
      terms = ComputeTerms(view, result.reference_T_current, points, options.depth_noise);
      eq = Accumulate(terms, EstimateScales(terms, options), options);
    }
  }
  Assess(terms, eq, options, &result);
  return result;
}

}  // namespace plx

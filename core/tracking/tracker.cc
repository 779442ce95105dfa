#include "core/tracking/tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/elapsed.h"
#include "core/common/status_macros.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/refresh_occupancy.h"

namespace plx {
namespace {

Eigen::Matrix<double, 6, 6> UnpackNormal(const TrackingSums& s) {
  Eigen::Matrix<double, 6, 6> H;
  int k = 0;
  for (int i = 0; i < kPoseDim; ++i) {
    for (int j = i; j < kPoseDim; ++j) H(i, j) = H(j, i) = s.H[k++];
  }
  return H;
}

}  // namespace

const char* TrackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kOk: return "OK";
    case TrackingState::kDegraded: return "DEGRADED";
    case TrackingState::kLost: return "LOST";
  }
  return "?";
}

Tracker::Tracker(const PlenoxelMap* map, Backend* backend, const TrackerOptions& options)
    : map_(map), backend_(backend), options_(options) {}

absl::Status Tracker::ValidateOptions(const TrackerOptions& o) {
  if (o.rays < kMinTrackerRays || o.rays > kMaxTrackerRays) {
    return absl::InvalidArgumentError(absl::StrCat("rays must be in [", kMinTrackerRays, ", ",
                                                   kMaxTrackerRays, "], got ", o.rays));
  }
  if (o.iterations < 1 || o.iterations > kMaxTrackerIterations) {
    return absl::InvalidArgumentError(
        absl::StrCat("iterations must be in [1, ", kMaxTrackerIterations, "], got ", o.iterations));
  }
  if (!(o.huber_k > 0) || !(o.params.color_sigma > 0) || o.coarse_divisor < 1) {
    return absl::InvalidArgumentError("huber_k, colour sigma and coarse divisor must be positive");
  }
  if (!(o.time_budget_ms >= 0.0) || !std::isfinite(o.time_budget_ms)) {
    return absl::InvalidArgumentError(
        absl::StrCat("time_budget_ms must be 0 (none) or positive, got ", o.time_budget_ms));
  }
  if (!o.params.use_color && !o.params.use_depth) {
    return absl::InvalidArgumentError("tracking needs colour, depth or both");
  }
  return absl::OkStatus();
}

void Tracker::Reset(const SE3& world_T_camera, double timestamp) {
  last_pose_ = world_T_camera;
  last_timestamp_ = timestamp;
  velocity_.reset();
}

SE3 Tracker::Predict(double timestamp) const {
  if (!options_.constant_velocity || !velocity_) return last_pose_;
  const double dt = timestamp - last_timestamp_;
  if (!(dt > 0.0) || dt > 1.0) return last_pose_;  // out of order or a long gap: no guess
  return last_pose_ * SE3::Exp(*velocity_ * dt);
}

void Tracker::SamplePixels(const RgbdFrame& frame, int count, PixelSampling sampling) {
  // A fresh draw per frame; the first rays / coarse_divisor of the list serve the coarse level.
  std::mt19937 rng(options_.seed ^ (frame_counter_ * 2654435761u));
  PixelSelectionOptions selection;
  selection.sampling = sampling;
  selection.max_depth = options_.params.max_depth;
  SelectTrackingPixels(frame, selection, count, &rng, &selection_scratch_, &pixels_);
}

absl::StatusOr<TrackingSums> Tracker::Evaluate(const SE3& pose, const RgbdFrame& frame,
                                               const PinholeIntrinsics& k, int rays,
                                               TrackingLoss loss, float scale[2],
                                               bool estimate_scale) {
  TrainingFrameView view;
  view.camera = ToKernelCamera(pose, k);
  view.color = frame.color.data.data();
  view.depth = frame.depth.data.data();
  terms_.resize(static_cast<size_t>(rays));
  PLX_RETURN_IF_ERROR(backend_->ComputeTrackingTerms(map_->grid.view(), view, pixels_.data(),
                                                     rays, options_.params, terms_.data()));
  if (estimate_scale) RobustScales(rays, scale);
  TrackingSums sums;
  PLX_RETURN_IF_ERROR(
      backend_->ReduceTrackingTerms(terms_.data(), rays, loss, options_.huber_k, scale, &sums));
  return sums;
}

void Tracker::RobustScales(int rays, float scale[2]) {
  // 1.4826 * median |e| estimates the spread of the scaled residuals; far from the optimum it
  // is much larger than 1 (the sensor noise), and stretching the noise scales to it keeps the
  // Huber weights from flattening every residual into an L1 step.
  for (int group = 0; group < 2; ++group) {
    scratch_.clear();
    for (int i = 0; i < rays; ++i) {
      const TrackingRayTerm& t = terms_[i];
      for (int n = group == 0 ? 0 : 3; n < (group == 0 ? 3 : 4); ++n) {
        if (t.weight[n] > 0.0f) scratch_.push_back(std::fabs(t.residual[n] * t.weight[n]));
      }
    }
    if (scratch_.size() < 16) continue;
    auto mid = scratch_.begin() + scratch_.size() / 2;
    std::nth_element(scratch_.begin(), mid, scratch_.end());
    scale[group] = std::max(1.0f, 1.4826f * *mid);
  }
}

absl::Status Tracker::RunGaussNewton(const RgbdFrame& frame, const PinholeIntrinsics& k,
                                     std::chrono::steady_clock::time_point start, SE3* pose,
                                     TrackingResult* result, TrackingSums* last) {
  const int total = static_cast<int>(pixels_.size());
  const int coarse_rays = std::max(16, total / options_.coarse_divisor);
  const int coarse_iterations = options_.coarse_divisor > 1 ? options_.iterations / 2 : 0;
  int iteration = 0;
  for (int level = 0; level < 2; ++level) {
    const int rays = level == 0 ? coarse_rays : total;
    const int budget = level == 0 ? coarse_iterations : options_.iterations - coarse_iterations;
    if (budget <= 0) continue;
    const float color_stretch = level == 0 ? options_.coarse_color_scale : 1.0f;
    float scale[2] = {color_stretch, 1.0f};
    SE3 accepted = *pose;
    TrackingSums accepted_sums;
    bool have_accepted = false;
    double lambda = 1e-4;
    double iteration_ms = 0.0;  // the level's last iteration, the pace of the next
    for (int it = 0; it < budget; ++it, ++iteration) {
      if (options_.time_budget_ms > 0.0 && it > 0) {
        // The coarse level keeps room for the fine level's first iteration (its rays are
        // coarse_divisor times as many).
        const double next = iteration_ms * (level == 0 ? 1 + options_.coarse_divisor : 1);
        if (MillisecondsSince(start) + next > options_.time_budget_ms) {
          result->out_of_time = true;
          break;
        }
      }
      const double iteration_start = MillisecondsSince(start);
      PLX_ASSIGN_OR_RETURN(TrackingSums sums,
                           Evaluate(*pose, frame, k, rays, TrackingLoss::kHuber, scale,
                                    options_.adaptive_scale && it == 0));
      scale[0] = std::max(scale[0], color_stretch);
      const double cost = sums.valid_rays > 0 ? sums.cost / sums.residual_count : HUGE_VAL;
      const double accepted_cost =
          have_accepted ? accepted_sums.cost / accepted_sums.residual_count : HUGE_VAL;
      if (sums.valid_rays < kPoseDim || (have_accepted && cost > accepted_cost)) {
        // The step made things worse (or left the map): go back and damp harder.
        if (!have_accepted) {
          *last = sums;
          result->iterations = iteration + 1;
          return absl::OkStatus();
        }
        *pose = accepted;
        sums = accepted_sums;
        lambda = std::min(lambda * 10.0, 1e4);
      } else {
        accepted = *pose;
        accepted_sums = sums;
        have_accepted = true;
        lambda = std::max(lambda * 0.1, 1e-7);
      }
      *last = accepted_sums;
      Eigen::Matrix<double, 6, 6> H = UnpackNormal(sums);
      const Eigen::Matrix<double, 6, 1> g = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(sums.g);
      H.diagonal() += lambda * H.diagonal() + Eigen::Matrix<double, 6, 1>::Constant(1e-9);
      const Vector6d delta = H.ldlt().solve(-g);
      if (!delta.allFinite()) break;
      *pose = accepted * SE3::Exp(delta);
      iteration_ms = MillisecondsSince(start) - iteration_start;
      if (delta.head<3>().norm() < options_.converged_translation &&
          delta.tail<3>().norm() < options_.converged_rotation) {
        ++iteration;
        break;
      }
    }
  }
  result->iterations = iteration;
  return absl::OkStatus();
}

absl::Status Tracker::RunAdam(const RgbdFrame& frame, const PinholeIntrinsics& k, SE3* pose,
                              TrackingResult* result, TrackingSums* last) {
  Vector6d m = Vector6d::Zero(), v = Vector6d::Zero();
  const double beta1 = 0.9, beta2 = 0.999, eps = 1e-8;
  TrackingParams saved = options_.params;
  options_.params.l1_paper_weights = true;
  for (int it = 0; it < options_.iterations; ++it) {
    SamplePixels(frame, options_.rays, PixelSampling::kUniform);  // new rays every step (paper)
    ++frame_counter_;
    float unit[2] = {1.0f, 1.0f};
    absl::StatusOr<TrackingSums> evaluated = Evaluate(
        *pose, frame, k, static_cast<int>(pixels_.size()), TrackingLoss::kL1, unit, false);
    if (!evaluated.ok()) {
      options_.params = saved;
      return evaluated.status();
    }
    const TrackingSums& sums = *evaluated;
    *last = sums;
    if (sums.valid_rays < kPoseDim) break;
    const Vector6d g = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(sums.g) / sums.valid_rays;
    m = beta1 * m + (1 - beta1) * g;
    v = beta2 * v + (1 - beta2) * g.cwiseProduct(g);
    const Vector6d m_hat = m / (1 - std::pow(beta1, it + 1));
    const Vector6d v_hat = v / (1 - std::pow(beta2, it + 1));
    const double lr =
        options_.adam_lr * std::pow(options_.adam_decay, it / options_.adam_decay_every);
    const Vector6d step = -lr * m_hat.cwiseQuotient((v_hat.cwiseSqrt().array() + eps).matrix());
    *pose = *pose * SE3::Exp(step);
    result->iterations = it + 1;
  }
  options_.params = saved;
  // Score the final pose with the Gauss-Newton residuals so states mean the same in both modes.
  SamplePixels(frame, options_.rays, PixelSampling::kUniform);
  float unit[2] = {1.0f, 1.0f};
  PLX_ASSIGN_OR_RETURN(*last, Evaluate(*pose, frame, k, static_cast<int>(pixels_.size()),
                                       TrackingLoss::kHuber, unit, false));
  return absl::OkStatus();
}

void Tracker::Classify(const SE3& predicted, const TrackingSums& last,
                       TrackingResult* result) const {
  result->valid_rays = static_cast<int>(last.valid_rays);
  result->residual_rms =
      last.residual_count > 0 ? std::sqrt(last.residual_sq / last.residual_count) : 0.0;
  const double valid_fraction = result->rays > 0 ? last.valid_rays / result->rays : 0.0;
  const SE3 moved = predicted.Inverse() * result->pose;
  const double translation = moved.translation().norm();
  const double rotation = RotationAngleBetween(predicted, result->pose);
  result->cause = TrackingCause::kNone;
  if (valid_fraction < options_.lost_valid_fraction) {
    result->state = TrackingState::kLost;
    result->cause = TrackingCause::kFewValidRays;
    result->reason = absl::StrFormat("too few valid rays: %d of %d hit the map", result->valid_rays,
                                     result->rays);
  } else if (!result->pose.IsFinite() || translation > options_.lost_translation ||
             rotation > options_.lost_rotation) {
    result->state = TrackingState::kLost;
    result->cause = TrackingCause::kDiverged;
    result->reason = absl::StrFormat("diverged: %.2f m / %.1f deg from the prediction",
                                     translation, rotation * 180.0 / M_PI);
  } else if (result->residual_rms > options_.lost_rms) {
    result->state = TrackingState::kLost;
    result->cause = TrackingCause::kHighResidual;
    result->reason = absl::StrFormat("residual too high (RMS %.2f)", result->residual_rms);
  } else if (valid_fraction < options_.degraded_valid_fraction) {
    result->state = TrackingState::kDegraded;
    result->cause = TrackingCause::kFewValidRays;
    result->reason = absl::StrFormat("few valid rays: %d of %d", result->valid_rays, result->rays);
  } else if (result->residual_rms > options_.degraded_rms) {
    result->state = TrackingState::kDegraded;
    result->cause = TrackingCause::kHighResidual;
    result->reason = absl::StrFormat("high residual (RMS %.2f)", result->residual_rms);
  } else {
    result->state = TrackingState::kOk;
    result->reason.clear();
  }
}

absl::StatusOr<TrackingResult> Tracker::Track(const RgbdFrame& frame,
                                              const PinholeIntrinsics& k,
                                              const std::optional<SE3>& prior) {
  const auto start = std::chrono::steady_clock::now();
  TrackingResult result;
  const SE3 predicted = prior ? *prior : Predict(frame.timestamp);
  SE3 pose = predicted;
  result.rays = options_.rays;
  TrackingSums last;
  last.Clear();
  const bool sizes_ok = frame.color.width == k.width && frame.color.height == k.height &&
                        frame.depth.width == k.width && frame.depth.height == k.height &&
                        frame.color.channels == 3 && frame.depth.channels == 1;
  if (sizes_ok && map_->grid.num_bricks() > 0) {
    options_.params.render = map_->render;
    if (options_.mode == TrackingMode::kGaussNewton) {
      SamplePixels(frame, options_.rays, options_.sampling);
      ++frame_counter_;
      if (!pixels_.empty()) {
        PLX_RETURN_IF_ERROR(RunGaussNewton(frame, k, start, &pose, &result, &last));
      }
    } else {
      PLX_RETURN_IF_ERROR(RunAdam(frame, k, &pose, &result, &last));
    }
  }
  result.pose = pose;
  Classify(predicted, last, &result);
  if (!sizes_ok) result.reason = "frame size does not match the intrinsics";
  if (result.state == TrackingState::kLost) {
    result.pose = predicted;  // never hand out an unconverged estimate
  } else {
    const double dt = frame.timestamp - last_timestamp_;
    if (dt > 0.0) velocity_ = (last_pose_.Inverse() * result.pose).Log() / dt;
    last_pose_ = result.pose;
    last_timestamp_ = frame.timestamp;
  }
  result.milliseconds = MillisecondsSince(start);
  return result;
}

}  // namespace plx

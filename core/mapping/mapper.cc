#include "core/mapping/mapper.h"

#include <chrono>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/mapping/learning_rate.h"
#include "core/math/hash.h"

namespace plx {
namespace {

// Iterations between exact recomputations of cell occupancy.
constexpr int kOccupancyRefreshInterval = 100;

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

MapperOptions MapperOptionsForVoxelSize(float voxel_size) {
  MapperOptions o;
  o.voxel_size = voxel_size;
  o.allocation.min_band = 4.0f * voxel_size;
  o.fusion.min_truncation = 4.0f * voxel_size;
  o.fusion.ramp = 1.0f * voxel_size;
  o.fusion.color_band = 1.5f * voxel_size;
  return o;
}

Mapper::Mapper(const MapperOptions& options, Backend* backend)
    : options_(options),
      backend_(backend),
      map_(std::make_unique<PlenoxelMap>(options.voxel_size * (options.coarse_to_fine ? 2 : 1))),
      coarse_(options.coarse_to_fine) {
  map_->render = options.render;
}

Mapper::Mapper(const MapperOptions& options, Backend* backend, std::unique_ptr<PlenoxelMap> map)
    : options_(options), backend_(backend), map_(std::move(map)) {
  options_.voxel_size = map_->grid.voxel_size();
  options_.coarse_to_fine = false;
  ResizeOptimizerBuffers();
}

absl::StatusOr<std::shared_ptr<const PlenoxelMap>> Mapper::Publish() {
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
  return CatchAllocationFailure("publishing the map",
                                [&]() -> absl::StatusOr<std::shared_ptr<const PlenoxelMap>> {
                                  return std::make_shared<const PlenoxelMap>(map_->Publish());
                                });
}

absl::Status Mapper::ValidateOptions(const MapperOptions& o) {
  if (!(o.voxel_size >= 0.001f && o.voxel_size <= 1.0f)) {
    return absl::InvalidArgumentError(
        absl::StrCat("voxel size must be in [0.001, 1] m, got ", o.voxel_size));
  }
  if (o.max_iterations < 0 || o.time_budget_s < 0) {
    return absl::InvalidArgumentError("iteration and time budgets must not be negative");
  }
  if (o.max_iterations == 0 && o.time_budget_s == 0) {
    return absl::InvalidArgumentError("set an iteration budget, a time budget, or both");
  }
  if (o.batch_size <= 0 || o.batch_size > (1 << 24)) {
    return absl::InvalidArgumentError(absl::StrCat("batch size out of range: ", o.batch_size));
  }
  if (o.window_keyframes < 0 || !(o.window_fraction >= 0.0f && o.window_fraction <= 1.0f)) {
    return absl::InvalidArgumentError(
        "window_keyframes must not be negative and window_fraction must be in [0, 1]");
  }
  if (o.coarse_to_fine && !(o.upsample_at > 0.0f && o.upsample_at < 1.0f)) {
    return absl::InvalidArgumentError("upsample_at must be inside (0, 1)");
  }
  if (!(o.allocation.max_depth > 0) || !(o.allocation.min_band > 0)) {
    return absl::InvalidArgumentError("allocation band and max depth must be positive");
  }
  return absl::OkStatus();
}

absl::Status Mapper::AddKeyframe(RgbdFrame frame, const SE3& world_T_camera,
                                 const PinholeIntrinsics& intrinsics) {
  return training_.AddFrame(std::move(frame), world_T_camera, intrinsics,
                            options_.allocation.max_depth);
}

void Mapper::ResizeOptimizerBuffers() {
  const size_t n = static_cast<size_t>(map_->grid.num_vertices());
  grad_density_.resize(n, 0.0f);
  grad_sh_.resize(n * kShCoeffCount, 0.0f);
  touched_.resize(n, 0);
  brick_touched_.resize(static_cast<size_t>(map_->grid.num_bricks()), 0);
  rms_density_.resize(n, 0.0f);
  rms_sh_.resize(n * kShCoeffCount, 0.0f);
}

GridGradView Mapper::grad_view() {
  return GridGradView{grad_density_.data(), grad_sh_.data(), touched_.data(),
                      brick_touched_.data()};
}

OptimizerStateView Mapper::state_view() {
  return OptimizerStateView{rms_density_.data(), rms_sh_.data()};
}

absl::Status Mapper::AllocateFrames(int first_frame, PlenoxelMap& map, float voxel_size) {
  const float init = options_.initialize_from_depth ? 0.0f : options_.initial_density;
  for (int f = first_frame; f < training_.num_frames(); ++f) {
    const std::vector<BrickCoord> bricks =
        BricksNearSurface(training_.frame(f).depth, training_.pose(f), training_.intrinsics(f),
                          voxel_size, options_.allocation);
    PLX_ASSIGN_OR_RETURN(int64_t added, map.grid.AllocateBricks(bricks, init));
    (void)added;
  }
  return absl::OkStatus();
}

absl::Status Mapper::AllocateAndInitialize() {
  const auto start = std::chrono::steady_clock::now();
  const int64_t first_new_vertex = map_->grid.num_vertices();
  PLX_RETURN_IF_ERROR(AllocateFrames(allocated_frames_, *map_, map_->grid.voxel_size()));
  allocated_frames_ = training_.num_frames();
  const int64_t new_vertices = map_->grid.num_vertices() - first_new_vertex;
  if (options_.initialize_from_depth && new_vertices > 0) {
    const UnifiedVector<TrainingFrameView>& frames = training_.frame_views();
    PLX_RETURN_IF_ERROR(backend_->FuseDepth(map_->grid.view(), map_->grid.write_view(),
                                            first_new_vertex, new_vertices, frames.data(),
                                            static_cast<int>(frames.size()), options_.fusion));
  }
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
  ResizeOptimizerBuffers();
  summary_.allocation_s += Seconds(start);
  summary_.keyframes = training_.num_frames();
  summary_.training_rays = training_.num_rays();
  summary_.memory = map_->grid.Memory();
  return absl::OkStatus();
}

absl::Status Mapper::Upsample() {
  auto fine = std::make_unique<PlenoxelMap>(options_.voxel_size);
  fine->render = map_->render;
  PLX_RETURN_IF_ERROR(AllocateFrames(0, *fine, options_.voxel_size));
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
  PLX_RETURN_IF_ERROR(
      backend_->ResampleGrid(fine->grid.view(), fine->grid.write_view(), map_->grid.view()));
  map_ = std::move(fine);
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
  for (auto* buffer : {&grad_density_, &grad_sh_, &rms_density_, &rms_sh_}) buffer->clear();
  touched_.clear();
  brick_touched_.clear();
  ResizeOptimizerBuffers();
  coarse_ = false;
  summary_.upsampled = true;
  return absl::OkStatus();
}

absl::StatusOr<MappingSummary> Mapper::Optimize(const MappingProgressCallback& progress,
                                                int max_new_iterations, double max_seconds) {
  PLX_RETURN_IF_ERROR(ValidateOptions(options_));
  if (allocated_frames_ != training_.num_frames()) PLX_RETURN_IF_ERROR(AllocateAndInitialize());
  if (training_.num_rays() == 0) {
    return absl::FailedPreconditionError(
        "no keyframe has valid depth within the depth range: nothing to map");
  }
  if (map_->grid.num_bricks() == 0) {
    return absl::FailedPreconditionError("no bricks were allocated from the keyframes' depth");
  }
  const auto start = std::chrono::steady_clock::now();
  losses_.resize(options_.batch_size);
  const TrainingRaysView rays = training_.rays_view(options_.window_keyframes);
  MappingBatchParams batch;
  batch.batch_size = options_.batch_size;
  if (rays.recent_begin > 0) {
    batch.recent_batch =
        static_cast<int64_t>(options_.window_fraction * static_cast<float>(options_.batch_size));
  }
  batch.depth_weight = options_.depth_weight;
  batch.depth_huber = options_.depth_huber;
  batch.depth_noise = options_.fusion.noise;
  batch.sh_min_weight = options_.sh_min_weight;
  batch.render = map_->render;
  RmsPropParams rms;
  rms.beta = options_.rmsprop_beta;
  rms.sigma_threshold = map_->render.sigma_threshold;
  int64_t tv_count = std::max<int64_t>(
      1, static_cast<int64_t>(options_.tv_fraction * map_->grid.num_vertices()));

  MappingProgress last;
  int done = 0;
  for (;;) {
    const double elapsed = Seconds(start);
    // The budget counts every iteration and second spent by earlier calls too, so a map that is
    // optimised in chunks (the daemon) follows one learning-rate schedule.
    double fraction = 0.0;
    if (options_.max_iterations > 0) fraction = double(iteration_) / options_.max_iterations;
    if (options_.time_budget_s > 0) {
      fraction = std::max(fraction, (summary_.optimization_s + elapsed) / options_.time_budget_s);
    }
    if (fraction >= 1.0) break;
    // The schedule only moves forward: a budget raised as keyframes stream in (a mapping
    // session) lowers iteration / budget, but the learning rate must not climb back up and
    // shake the bricks that have already converged.
    schedule_ = std::max(schedule_, fraction);
    if (max_new_iterations > 0 && done >= max_new_iterations) break;
    if (max_seconds > 0 && done > 0 && elapsed >= max_seconds) break;
    if (coarse_ && fraction >= options_.upsample_at) {
      PLX_RETURN_IF_ERROR(Upsample());
      tv_count = std::max<int64_t>(
          1, static_cast<int64_t>(options_.tv_fraction * map_->grid.num_vertices()));
    }

    const GridView grid = map_->grid.view();
    const GridGradView grad = grad_view();
    batch.seed = options_.seed + static_cast<uint32_t>(iteration_) * 7919u;
    PLX_RETURN_IF_ERROR(backend_->MappingForwardBackward(grid, grad, rays, batch, losses_.data()));
    if ((options_.tv_density > 0 || options_.tv_sh > 0) && fraction < options_.tv_until) {
      const int64_t first = static_cast<int64_t>(
          HashIndex(batch.seed ^ 0x5bd1e995u, 0, static_cast<uint64_t>(grid.num_vertices())));
      PLX_RETURN_IF_ERROR(backend_->AddTvGradient(grid, grad, first, tv_count,
                                                  options_.tv_density, options_.tv_sh));
    }
    rms.lr_density = static_cast<float>(
        LogLinearLearningRate(options_.lr_density_start, options_.lr_density_end, schedule_));
    rms.lr_sh = static_cast<float>(
        LogLinearLearningRate(options_.lr_sh_start, options_.lr_sh_end, schedule_));
    // The step writes the bricks that received gradient: clone those a published version
    // still shares (copy-on-write), then take the views again (the tables changed).
    deferred_.clear();
    summary_.cloned_bricks += map_->grid.MakePrivate(
        brick_touched_.data(),
        options_.max_clones_per_iteration > 0 ? options_.max_clones_per_iteration : -1,
        &deferred_);
    // Bricks still shared sit this step out: their vertices keep gradient and touched flags,
    // and their brick flags are raised again for the next step.
    for (int64_t slot : deferred_) brick_touched_[slot] = 0;
    PLX_RETURN_IF_ERROR(backend_->RmsPropStep(map_->grid.view(), map_->grid.write_view(), grad,
                                              state_view(), rms));
    for (int64_t slot : deferred_) brick_touched_[slot] = 1;
    ++iteration_;
    ++done;
    if (done % kOccupancyRefreshInterval == 0) {
      // Densities only mark cells occupied on the way up; drop the cells that emptied since.
      map_->grid.mark_occupancy_stale();
      PLX_RETURN_IF_ERROR(
          RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
    }

    const bool report = progress && (done % options_.progress_every == 0 || done == 1);
    if (report || options_.progress_every == 1) {
      double mse = 0.0, depth = 0.0, opacity = 0.0;
      for (const MappingRayLoss& l : losses_) {
        mse += l.color_sq / 3.0;
        depth += l.depth_abs;
        opacity += l.opacity;
      }
      const double n = static_cast<double>(losses_.size());
      last.iteration = iteration_;
      last.elapsed_s = Seconds(start);
      last.progress = fraction;
      last.psnr = -10.0 * std::log10(std::max(mse / n, 1e-12));
      last.depth_l1_m = depth / n;
      last.opacity = opacity / n;
      if (report && !progress(last)) break;
    }
  }
  summary_.iterations = iteration_;
  summary_.optimization_s += Seconds(start);
  summary_.last = last;
  summary_.memory = map_->grid.Memory();
  summary_.optimizer_bytes = static_cast<int64_t>(
      (grad_density_.size() + grad_sh_.size() + rms_density_.size() + rms_sh_.size()) *
          sizeof(float) +
      touched_.size() + brick_touched_.size());
  return summary_;
}

}  // namespace plx

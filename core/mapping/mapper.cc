#include "core/mapping/mapper.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/kernel_camera.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/mapping/learning_rate.h"
#include "core/math/hash.h"

namespace plx {
namespace {

using Clock = std::chrono::steady_clock;

// Iterations between exact recomputations of cell occupancy.
constexpr int kOccupancyRefreshInterval = 100;

// The first piece of each integration phase, before a rate is known, and the smallest piece:
// a few milliseconds of work on a loaded 2-core machine.
constexpr int64_t kAllocationPieceBricks = 16;                // 56 KB of parameters each
constexpr int64_t kFusionPieceVertices = 8 * kBrickVertices;  // keyframes x vertices lookups
constexpr int64_t kOccupancyPieceBlocks = 256;                // 512 cells each
constexpr int64_t kBufferPieceBytes = int64_t{4} << 20;       // copied or zeroed

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// How fast a phase's pieces ran, so the next piece fills the time left.
struct Pace {
  double items_per_second = 0.0;
  int64_t last_piece = 0;
};

// Works through [*next, end) in pieces, piece(first, count), until it is done or `deadline`
// passes (at least one piece when anything is left). Each piece is sized from the rate of the
// one before to fill the time left, at most twice as large as that one (a rate measured on a
// small piece is a guess) and at least `min_piece`: a backend that pays per call (a CUDA launch
// and its prefetch of the grid) is called a few times per slice, not thousands. Without a
// deadline (time_point::max()) the whole range is one piece, as the unsliced code did it.
template <typename Piece>
absl::Status RunPaced(int64_t* next, int64_t end, int64_t min_piece, Clock::time_point deadline,
                      Pace* pace, Piece&& piece) {
  while (*next < end) {
    int64_t count = end - *next;
    if (deadline != Clock::time_point::max()) {
      const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
      int64_t fits = static_cast<int64_t>(pace->items_per_second * std::max(left, 0.0));
      if (pace->last_piece > 0) fits = std::min(fits, 2 * pace->last_piece);
      count = std::min(count, std::max(min_piece, fits));
    }
    const auto start = Clock::now();
    PLX_RETURN_IF_ERROR(piece(*next, count));
    const double seconds = Seconds(start);
    if (seconds > 0.0) pace->items_per_second = static_cast<double>(count) / seconds;
    pace->last_piece = count;
    *next += count;
    if (Clock::now() >= deadline) break;
  }
  return absl::OkStatus();
}

// Grows one optimiser buffer to `size` elements in pieces, its contents kept and the new
// elements zero. When the capacity is too small, the old contents are first copied into larger
// storage in runs (a vector's own reallocation would copy them all in one go: hundreds of MB on
// a large map), then the new elements are zeroed in runs (their pages are faulted in then).
// Work items: the elements copied, then the elements zeroed.
template <typename T>
class BufferGrowth {
 public:
  BufferGrowth(UnifiedVector<T>* buffer, size_t size) : buffer_(buffer) {
    if (buffer->capacity() < size) {
      if (buffer->empty()) {
        buffer->reserve(size);
      } else {
        larger_.reserve(std::max(size, 2 * buffer->size()));  // geometric, like resize
        to_copy_ = static_cast<int64_t>(buffer->size());
      }
    }
    items_ = to_copy_ + static_cast<int64_t>(size - buffer->size());
  }

  int64_t items() const { return items_; }

  absl::Status Advance(int64_t first, int64_t count) {
    const int64_t copy = std::clamp<int64_t>(to_copy_ - first, 0, count);
    if (copy > 0) {
      larger_.insert(larger_.end(), buffer_->begin() + first, buffer_->begin() + first + copy);
      if (first + copy == to_copy_) {
        buffer_->swap(larger_);
        UnifiedVector<T>().swap(larger_);  // the old storage goes now, inside a timed piece
      }
    }
    buffer_->resize(buffer_->size() + static_cast<size_t>(count - copy), T{});
    return absl::OkStatus();
  }

 private:
  UnifiedVector<T>* buffer_;
  UnifiedVector<T> larger_;
  int64_t to_copy_ = 0;
  int64_t items_ = 0;
};

}  // namespace

// The integration in progress (mapper.h, top): which phase, and where each one stands.
struct Mapper::Integration {
  enum class Phase { kList, kAllocate, kFuse, kOccupancy, kBuffers };
  Phase phase = Phase::kList;
  int first_frame = 0, end_frame = 0;  // keyframes [first_frame, end_frame) are integrated
  int frame = 0;                       // the keyframe being listed or allocated
  // The keyframes as the integration began: a pose refined meanwhile (SetKeyframePose) reaches
  // the map through optimisation, as it would have after an integration in one go.
  std::vector<SE3> poses;                  // of keyframes [first_frame, end_frame)
  UnifiedVector<TrainingFrameView> views;  // of keyframes [0, end_frame), read by fusion
  std::vector<BrickCoord> bricks;          // `frame`'s
  int64_t next_brick = 0;
  int64_t first_vertex = 0, next_vertex = 0;  // the new vertices start at first_vertex
  int64_t next_block = 0;                     // into the grid's active blocks
  // The optimiser buffers (in a fixed order), each growing by its own pieces.
  std::vector<std::function<absl::Status(Clock::time_point)>> buffers;
  size_t next_buffer = 0;
  Pace allocation, fusion, occupancy;
};

Mapper::~Mapper() = default;

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
  // Unfused bricks must not reach readers.
  if (integrating()) PLX_RETURN_IF_ERROR(IntegrateSlice(0.0).status());
  PLX_RETURN_IF_ERROR(RefreshOccupancyIfStale(*backend_, map_->grid, map_->render.sigma_threshold));
  return CatchAllocationFailure("publishing the map",
                                [&]() -> absl::StatusOr<std::shared_ptr<const PlenoxelMap>> {
                                  return std::make_shared<const PlenoxelMap>(map_->Publish());
                                });
}

absl::Status Mapper::ValidateOptions(const MapperOptions& o) {
  if (!VoxelSizeInRange(o.voxel_size)) {
    return absl::InvalidArgumentError(absl::StrCat("voxel size must be in [", kMinVoxelSize, ", ",
                                                   kMaxVoxelSize, "] m, got ", o.voxel_size));
  }
  if (o.max_iterations < 0 || o.time_budget_s < 0) {
    return absl::InvalidArgumentError("iteration and time budgets must not be negative");
  }
  if (o.max_iterations == 0 && o.time_budget_s == 0) {
    return absl::InvalidArgumentError("set an iteration budget, a time budget, or both");
  }
  if (o.batch_size <= 0 || o.batch_size > kMaxBatchSize) {
    return absl::InvalidArgumentError(absl::StrCat("batch size out of range: ", o.batch_size));
  }
  if (o.window_keyframes < 0 || !(o.window_fraction >= 0.0f && o.window_fraction <= 1.0f)) {
    return absl::InvalidArgumentError(
        "window_keyframes must not be negative and window_fraction must be in [0, 1]");
  }
  if (o.coarse_to_fine && !(o.upsample_at > 0.0f && o.upsample_at < 1.0f)) {
    return absl::InvalidArgumentError("upsample_at must be inside (0, 1)");
  }
  if (o.max_map_bytes < 0) return absl::InvalidArgumentError("max_map_bytes must not be negative");
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

absl::StatusOr<std::vector<BrickCoord>> Mapper::FrameBricks(int f, const SE3& pose,
                                                            const SparseGrid& grid) const {
  std::vector<BrickCoord> bricks =
      BricksNearSurface(training_.frame(f).depth, pose, training_.intrinsics(f),
                        grid.voxel_size(), options_.allocation);
  if (options_.max_map_bytes > 0) {
    // Before allocating: a keyframe that sees far or noisy depth can add gigabytes of bricks.
    const GridMemory after = grid.MemoryAfterAllocating(bricks);
    if (after.total_bytes() > options_.max_map_bytes) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "keyframe ", f, " would add ", after.bricks - grid.num_bricks(),
          " bricks and take the map to ", after.total_bytes() / 1000000,
          " MB, over the limit of ", options_.max_map_bytes / 1000000,
          " MB per map; nothing was allocated"));
    }
  }
  return bricks;
}

absl::Status Mapper::AllocateFrames(int first_frame, PlenoxelMap& map) {
  const float init = options_.initialize_from_depth ? 0.0f : options_.initial_density;
  for (int f = first_frame; f < training_.num_frames(); ++f) {
    PLX_ASSIGN_OR_RETURN(const std::vector<BrickCoord> bricks,
                         FrameBricks(f, training_.pose(f), map.grid));
    PLX_RETURN_IF_ERROR(map.grid.AllocateBricks(bricks, init).status());
  }
  return absl::OkStatus();
}

absl::Status Mapper::AllocateAndInitialize() {
  while (integrating() || integrated_frames_ < training_.num_frames()) {
    PLX_RETURN_IF_ERROR(IntegrateSlice(0.0).status());
  }
  return absl::OkStatus();
}

absl::StatusOr<bool> Mapper::IntegrateSlice(double max_seconds) {
  if (!integrating()) {
    if (integrated_frames_ == training_.num_frames()) return true;
    StartIntegration();
  }
  const auto start = Clock::now();
  const Clock::time_point deadline =
      max_seconds > 0.0
          ? start + std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double>(max_seconds))
          : Clock::time_point::max();
  absl::Status status;
  do {
    status = AdvanceIntegration(deadline);
  } while (status.ok() && integrating() && Clock::now() < deadline);
  summary_.allocation_s += Seconds(start);
  PLX_RETURN_IF_ERROR(status);
  return !integrating();
}

void Mapper::StartIntegration() {
  auto in = std::make_unique<Integration>();
  in->first_frame = integrated_frames_;
  in->end_frame = training_.num_frames();
  in->frame = in->first_frame;
  for (int f = in->first_frame; f < in->end_frame; ++f) in->poses.push_back(training_.pose(f));
  const UnifiedVector<TrainingFrameView>& views = training_.frame_views();
  in->views.assign(views.begin(), views.end());
  in->first_vertex = map_->grid.num_vertices();
  integration_ = std::move(in);
}

absl::Status Mapper::AdvanceIntegration(Clock::time_point deadline) {
  using Phase = Integration::Phase;
  Integration& in = *integration_;
  SparseGrid& grid = map_->grid;
  switch (in.phase) {
    case Phase::kList: {
      // One piece: the brick list is a hash set over the keyframe's pixels.
      PLX_ASSIGN_OR_RETURN(in.bricks,
                           FrameBricks(in.frame, in.poses[in.frame - in.first_frame], grid));
      PLX_RETURN_IF_ERROR(grid.PrepareToAllocate(in.bricks));
      in.next_brick = 0;
      in.phase = Phase::kAllocate;
      return absl::OkStatus();
    }
    case Phase::kAllocate: {
      const float init = options_.initialize_from_depth ? 0.0f : options_.initial_density;
      const absl::Span<const BrickCoord> bricks(in.bricks);
      PLX_RETURN_IF_ERROR(RunPaced(
          &in.next_brick, static_cast<int64_t>(bricks.size()), kAllocationPieceBricks, deadline,
          &in.allocation, [&](int64_t first, int64_t count) {
            return grid.AllocateBricks(bricks.subspan(first, count), init).status();
          }));
      if (in.next_brick < static_cast<int64_t>(bricks.size())) return absl::OkStatus();
      std::vector<BrickCoord>().swap(in.bricks);
      ++in.frame;
      in.next_vertex = in.first_vertex;
      in.phase = in.frame < in.end_frame ? Phase::kList : Phase::kFuse;
      return absl::OkStatus();
    }
    case Phase::kFuse: {
      if (options_.initialize_from_depth) {
        PLX_RETURN_IF_ERROR(RunPaced(
            &in.next_vertex, grid.num_vertices(), kFusionPieceVertices, deadline, &in.fusion,
            [&](int64_t first, int64_t count) {
              return backend_->FuseDepth(grid.view(), grid.write_view(), first, count,
                                         in.views.data(), static_cast<int>(in.views.size()),
                                         options_.fusion);
            }));
        if (in.next_vertex < grid.num_vertices()) return absl::OkStatus();
      }
      in.next_block = 0;
      in.phase = Phase::kOccupancy;
      return absl::OkStatus();
    }
    case Phase::kOccupancy: {
      // As RefreshOccupancyIfStale, by runs of blocks: the grid stays stale until the last run.
      if (grid.occupancy_stale()) {
        const UnifiedVector<int64_t>& blocks = grid.active_blocks();
        const float threshold = map_->render.sigma_threshold;
        PLX_RETURN_IF_ERROR(RunPaced(
            &in.next_block, static_cast<int64_t>(blocks.size()), kOccupancyPieceBlocks, deadline,
            &in.occupancy, [&](int64_t first, int64_t count) {
              return backend_->RefreshOccupancy(grid.view(), grid.write_view(),
                                                blocks.data() + first, count, threshold);
            }));
        if (in.next_block < static_cast<int64_t>(blocks.size())) return absl::OkStatus();
        grid.set_occupancy_fresh();
      }
      StartBufferGrowth();
      in.phase = Phase::kBuffers;
      return absl::OkStatus();
    }
    case Phase::kBuffers: {
      while (in.next_buffer < in.buffers.size()) {
        PLX_RETURN_IF_ERROR(in.buffers[in.next_buffer](deadline));
        if (Clock::now() >= deadline) return absl::OkStatus();
      }
      FinishIntegration();
      return absl::OkStatus();
    }
  }
  return absl::InternalError("unknown integration phase");
}

void Mapper::StartBufferGrowth() {
  Integration& in = *integration_;
  const size_t n = static_cast<size_t>(map_->grid.num_vertices());
  auto add = [&in](auto* buffer, size_t size) {
    using T = typename std::remove_pointer_t<decltype(buffer)>::value_type;
    auto growth = std::make_shared<BufferGrowth<T>>(buffer, size);
    auto next = std::make_shared<int64_t>(0);
    auto pace = std::make_shared<Pace>();
    in.buffers.push_back([&in, growth, next, pace](Clock::time_point deadline) -> absl::Status {
      PLX_RETURN_IF_ERROR(RunPaced(next.get(), growth->items(),
                                   std::max<int64_t>(1, kBufferPieceBytes / sizeof(T)), deadline,
                                   pace.get(), [&](int64_t first, int64_t count) {
                                     return growth->Advance(first, count);
                                   }));
      if (*next == growth->items()) ++in.next_buffer;
      return absl::OkStatus();
    });
  };
  // The sizes ResizeOptimizerBuffers gives.
  add(&grad_density_, n);
  add(&grad_sh_, n * kShCoeffCount);
  add(&touched_, n);
  add(&brick_touched_, static_cast<size_t>(map_->grid.num_bricks()));
  add(&rms_density_, n);
  add(&rms_sh_, n * kShCoeffCount);
}

void Mapper::FinishIntegration() {
  integrated_frames_ = integration_->end_frame;
  integration_.reset();
  summary_.keyframes = training_.num_frames();
  summary_.training_rays = training_.num_rays();
  summary_.memory = map_->grid.Memory();
}

absl::Status Mapper::Upsample() {
  auto fine = std::make_unique<PlenoxelMap>(options_.voxel_size);
  fine->render = map_->render;
  PLX_RETURN_IF_ERROR(AllocateFrames(0, *fine));
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
  PLX_RETURN_IF_ERROR(AllocateAndInitialize());
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

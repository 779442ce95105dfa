// The compute backend the algorithms run on (DESIGN.md §3): the kernel drivers of
// core/kernels/kernel_declarations.inc behind one interface, so mapping, tracking and rendering
// do not care whether they run on CPU threads or a GPU.
//
// Every call returns an absl::Status and never aborts: the public methods put their arguments
// in the kernel's argument struct (core/kernels/kernel_args.h), check them against what that
// struct lists (sizes not negative, required arrays not null, then its own value checks: an
// INVALID_ARGUMENT naming the kernel and the argument), turn an allocation failure
// (std::bad_alloc) into RESOURCE_EXHAUSTED and hand the struct to the backend's Launch, whose
// device errors come back as INTERNAL (or RESOURCE_EXHAUSTED for device memory), so one
// failing request does not take a daemon's other clients down. Every call returns after the
// work is done: results can be read right away.
//
// Views must point at memory the backend can read. CPU backend: any host memory. CUDA backend
// (cuda/cuda_backend.h): UnifiedVector memory (core/common/unified_allocator.h) allocated after
// the CUDA backend was created (CUDA managed memory), device memory of its GPU or pinned host
// memory; ordinary host memory (std::vector, the stack) fails the call with a message naming
// the argument. So every array a kernel touches lives in a UnifiedVector, and programs create
// their backend before they load maps or frames. Small parameter structs (the views
// themselves, options, `scale`) are passed by value and may live anywhere.
#pragma once

#include <memory>
#include <string>
#include <type_traits>

#include "absl/status/status.h"
#include "core/kernels/kernel_args.h"

namespace plx {

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Threads (CPU) or streaming multiprocessors (GPU) available, for reports.
  virtual int parallelism() const = 0;

  // See each kernel's argument struct (core/kernels/kernel_args.h) for what it computes.
  absl::Status RenderPixels(const GridView& grid, const CameraView& camera, const int32_t* pixels,
                            int64_t count, const RenderOptions& options, float* color, float* depth,
                            float* opacity, float* median_depth) {
    return Run(RenderPixelsArgs{.grid = grid,
                                .camera = camera,
                                .pixels = pixels,
                                .count = count,
                                .options = options,
                                .color = color,
                                .depth = depth,
                                .opacity = opacity,
                                .median_depth = median_depth});
  }
  absl::Status MappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                      const TrainingRaysView& rays,
                                      const MappingBatchParams& params, MappingRayLoss* losses) {
    return Run(MappingForwardBackwardArgs{
        .grid = grid, .grad = grad, .rays = rays, .params = params, .losses = losses});
  }
  absl::Status RmsPropStep(const GridView& grid, const GridWriteView& write,
                           const GridGradView& grad, const OptimizerStateView& state,
                           const RmsPropParams& params) {
    return Run(RmsPropStepArgs{
        .grid = grid, .write = write, .grad = grad, .state = state, .params = params});
  }
  absl::Status FuseDepth(const GridView& grid, const GridWriteView& write, int64_t first_vertex,
                         int64_t vertex_count, const TrainingFrameView* frames, int num_frames,
                         const FusionParams& params) {
    return Run(FuseDepthArgs{.grid = grid,
                             .write = write,
                             .first_vertex = first_vertex,
                             .vertex_count = vertex_count,
                             .frames = frames,
                             .num_frames = num_frames,
                             .params = params});
  }
  absl::Status ObserveSurface(const GridView& grid, const IsoBrickList& bricks,
                              const TrainingFrameView* frames, int num_frames,
                              const FusionParams& params, float* value) {
    return Run(ObserveSurfaceArgs{.grid = grid,
                                  .bricks = bricks,
                                  .frames = frames,
                                  .num_frames = num_frames,
                                  .params = params,
                                  .value = value});
  }
  absl::Status RefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                const int64_t* active_blocks, int64_t count, float threshold) {
    return Run(RefreshOccupancyArgs{.grid = grid,
                                    .write = write,
                                    .active_blocks = active_blocks,
                                    .count = count,
                                    .threshold = threshold});
  }
  absl::Status ComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                    const int32_t* pixels, int64_t count,
                                    const TrackingParams& params, TrackingRayTerm* terms) {
    return Run(ComputeTrackingTermsArgs{.grid = grid,
                                        .frame = frame,
                                        .pixels = pixels,
                                        .count = count,
                                        .params = params,
                                        .terms = terms});
  }
  absl::Status ReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count, TrackingLoss loss,
                                   float huber_k, const float scale[2], TrackingSums* sums) {
    return Run(ReduceTrackingTermsArgs{.terms = terms,
                                       .count = count,
                                       .loss = loss,
                                       .huber_k = huber_k,
                                       .scale = {scale[0], scale[1]},
                                       .sums = sums});
  }
  absl::Status ResampleGrid(const GridView& target, const GridWriteView& target_write,
                            const GridView& source) {
    return Run(ResampleGridArgs{.target = target, .target_write = target_write, .source = source});
  }
  absl::Status AddTvGradient(const GridView& grid, const GridGradView& grad, int64_t first_vertex,
                             int64_t vertex_count, float lambda_density, float lambda_sh) {
    return Run(AddTvGradientArgs{.grid = grid,
                                 .grad = grad,
                                 .first_vertex = first_vertex,
                                 .vertex_count = vertex_count,
                                 .lambda_density = lambda_density,
                                 .lambda_sh = lambda_sh});
  }
  absl::Status CountIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                 const IsoSurfaceParams& params, uint8_t* triangles,
                                 const IsoBrickList& bricks = {}) {
    return Run(CountIsoTrianglesArgs{.grid = grid,
                                     .first_vertex = first_vertex,
                                     .count = count,
                                     .params = params,
                                     .triangles = triangles,
                                     .bricks = bricks});
  }
  absl::Status EmitIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                const IsoSurfaceParams& params, const int64_t* first_triangle,
                                int64_t* edge_keys, const IsoBrickList& bricks = {}) {
    return Run(EmitIsoTrianglesArgs{.grid = grid,
                                    .first_vertex = first_vertex,
                                    .count = count,
                                    .params = params,
                                    .first_triangle = first_triangle,
                                    .edge_keys = edge_keys,
                                    .bricks = bricks});
  }
  absl::Status ComputeIsoVertices(const GridView& grid, const int64_t* edge_keys, int64_t count,
                                  const IsoSurfaceParams& params, float* positions, float* normals,
                                  uint8_t* colors, uint8_t* observed) {
    return Run(ComputeIsoVerticesArgs{.grid = grid,
                                      .edge_keys = edge_keys,
                                      .count = count,
                                      .params = params,
                                      .positions = positions,
                                      .normals = normals,
                                      .colors = colors,
                                      .observed = observed});
  }

 protected:
  // The implementation: runs the kernel whose arguments `args` holds, already checked against
  // the struct's list; returns device errors as a Status. Both backends forward every kernel
  // through one template to their driver Run(ctx, args) (kernel_declarations.inc).
  virtual absl::Status Launch(const KernelArgs& args) = 0;

  // A driver's result as a Status: the drivers that cannot fail return void.
  template <typename Driver>
  static absl::Status CallDriver(Driver&& driver) {
    if constexpr (std::is_void_v<decltype(driver())>) {
      driver();
      return absl::OkStatus();
    } else {
      return driver();
    }
  }

 private:
  // The checks the argument struct lists (backend.cc), then Launch.
  absl::Status Run(const KernelArgs& args);
};

// RefreshOccupancyIfStale: core/kernels/refresh_occupancy.h. MakeCpuBackend:
// core/cpu/cpu_backend.h.

}  // namespace plx

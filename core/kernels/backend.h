// The compute backend the algorithms run on (DESIGN.md §3): the kernel drivers of
// core/kernels/kernel_declarations.inc behind a virtual interface, so mapping, tracking and
// rendering do not care whether they run on CPU threads or a GPU.
//
// Views must point at memory the backend can read. CPU backend: any host memory. CUDA backend
// (cuda/cuda_backend.h): UnifiedVector memory (core/common/unified_allocator.h) allocated after
// the CUDA backend was created (CUDA managed memory), device memory of its GPU or pinned host
// memory; ordinary host memory (std::vector, the stack) makes the call abort with a message
// naming the argument. So every array a kernel touches lives in a UnifiedVector, and programs
// create their backend before they load maps or frames. Small parameter structs (the views
// themselves, options, `scale`) are passed by value and may live anywhere. Every call returns
// after the work is done: results can be read right away.
#pragma once

#include <memory>
#include <string>

#include "core/grid/grid_view.h"
#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"
#include "core/kernels/tracking_terms.h"

namespace plx {

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Threads (CPU) or streaming multiprocessors (GPU) available, for reports.
  virtual int parallelism() const = 0;

  virtual void RenderPixels(const GridView& grid, const CameraView& camera, const int32_t* pixels,
                            int64_t count, const RenderOptions& options, float* color,
                            float* depth, float* opacity, float* median_depth) = 0;
  virtual void MappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                      const TrainingRaysView& rays,
                                      const MappingBatchParams& params,
                                      MappingRayLoss* losses) = 0;
  virtual void RmsPropStep(const GridView& grid, const GridGradView& grad,
                           const OptimizerStateView& state, const RmsPropParams& params) = 0;
  virtual void FuseDepth(const GridView& grid, int64_t first_vertex, int64_t vertex_count,
                         const TrainingFrameView* frames, int num_frames,
                         const FusionParams& params) = 0;
  virtual void RefreshOccupancy(const GridView& grid, const int64_t* active_blocks, int64_t count,
                                float threshold) = 0;
  virtual void ComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                    const int32_t* pixels, int64_t count,
                                    const TrackingParams& params, TrackingRayTerm* terms) = 0;
  virtual TrackingSums ReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                           TrackingLoss loss, float huber_k,
                                           const float scale[2]) = 0;
  virtual void ResampleGrid(const GridView& target, const GridView& source) = 0;
  virtual void AddTvGradient(const GridView& grid, const GridGradView& grad,
                             int64_t first_vertex, int64_t vertex_count, float lambda_density,
                             float lambda_sh) = 0;
};

// RefreshOccupancyIfStale: core/kernels/refresh_occupancy.h. MakeCpuBackend:
// core/cpu/cpu_backend.h.

}  // namespace plx

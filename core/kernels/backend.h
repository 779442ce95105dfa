// The compute backend the algorithms run on (DESIGN.md §3): the kernel drivers of
// core/kernels/kernel_declarations.inc behind one interface, so mapping, tracking and rendering
// do not care whether they run on CPU threads or a GPU.
//
// Every call returns an absl::Status and never aborts: the public methods check their
// arguments, turn an allocation failure (std::bad_alloc) into RESOURCE_EXHAUSTED and call the
// backend's Do* implementation, whose device errors come back as INTERNAL (or
// RESOURCE_EXHAUSTED for device memory), so one failing request does not take a daemon's other
// clients down. Every call returns after the work is done: results can be read right away.
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

#include "absl/status/status.h"
#include "core/grid/grid_view.h"
#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"
#include "core/kernels/tracking_terms.h"

namespace plx {

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Threads (CPU) or streaming multiprocessors (GPU) available, for reports.
  virtual int parallelism() const = 0;

  // See core/kernels/kernel_declarations.inc for what each call computes.
  absl::Status RenderPixels(const GridView& grid, const CameraView& camera, const int32_t* pixels,
                            int64_t count, const RenderOptions& options, float* color,
                            float* depth, float* opacity, float* median_depth);
  absl::Status MappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                      const TrainingRaysView& rays,
                                      const MappingBatchParams& params, MappingRayLoss* losses);
  absl::Status RmsPropStep(const GridView& grid, const GridWriteView& write,
                           const GridGradView& grad, const OptimizerStateView& state,
                           const RmsPropParams& params);
  absl::Status FuseDepth(const GridView& grid, const GridWriteView& write, int64_t first_vertex,
                         int64_t vertex_count, const TrainingFrameView* frames, int num_frames,
                         const FusionParams& params);
  absl::Status RefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                const int64_t* active_blocks, int64_t count, float threshold);
  absl::Status ComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                    const int32_t* pixels, int64_t count,
                                    const TrackingParams& params, TrackingRayTerm* terms);
  absl::Status ReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                   TrackingLoss loss, float huber_k, const float scale[2],
                                   TrackingSums* sums);
  absl::Status ResampleGrid(const GridView& target, const GridWriteView& target_write,
                            const GridView& source);
  absl::Status AddTvGradient(const GridView& grid, const GridGradView& grad,
                             int64_t first_vertex, int64_t vertex_count, float lambda_density,
                             float lambda_sh);
  absl::Status CountIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                 const IsoSurfaceParams& params, uint8_t* triangles);
  absl::Status EmitIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                const IsoSurfaceParams& params, const int64_t* first_triangle,
                                int64_t* edge_keys);
  absl::Status ComputeIsoVertices(const GridView& grid, const int64_t* edge_keys, int64_t count,
                                  const IsoSurfaceParams& params, float* positions,
                                  float* normals, uint8_t* colors, uint8_t* observed);

 protected:
  // Implementations: called with checked arguments; return device errors as a Status.
  virtual absl::Status DoRenderPixels(const GridView& grid, const CameraView& camera,
                                      const int32_t* pixels, int64_t count,
                                      const RenderOptions& options, float* color, float* depth,
                                      float* opacity, float* median_depth) = 0;
  virtual absl::Status DoMappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                                const TrainingRaysView& rays,
                                                const MappingBatchParams& params,
                                                MappingRayLoss* losses) = 0;
  virtual absl::Status DoRmsPropStep(const GridView& grid, const GridWriteView& write,
                                     const GridGradView& grad, const OptimizerStateView& state,
                                     const RmsPropParams& params) = 0;
  virtual absl::Status DoFuseDepth(const GridView& grid, const GridWriteView& write,
                                   int64_t first_vertex, int64_t vertex_count,
                                   const TrainingFrameView* frames, int num_frames,
                                   const FusionParams& params) = 0;
  virtual absl::Status DoRefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                          const int64_t* active_blocks, int64_t count,
                                          float threshold) = 0;
  virtual absl::Status DoComputeTrackingTerms(const GridView& grid,
                                              const TrainingFrameView& frame,
                                              const int32_t* pixels, int64_t count,
                                              const TrackingParams& params,
                                              TrackingRayTerm* terms) = 0;
  virtual absl::Status DoReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                             TrackingLoss loss, float huber_k,
                                             const float scale[2], TrackingSums* sums) = 0;
  virtual absl::Status DoResampleGrid(const GridView& target, const GridWriteView& target_write,
                                      const GridView& source) = 0;
  virtual absl::Status DoAddTvGradient(const GridView& grid, const GridGradView& grad,
                                       int64_t first_vertex, int64_t vertex_count,
                                       float lambda_density, float lambda_sh) = 0;
  virtual absl::Status DoCountIsoTriangles(const GridView& grid, int64_t first_vertex,
                                           int64_t count, const IsoSurfaceParams& params,
                                           uint8_t* triangles) = 0;
  virtual absl::Status DoEmitIsoTriangles(const GridView& grid, int64_t first_vertex,
                                          int64_t count, const IsoSurfaceParams& params,
                                          const int64_t* first_triangle, int64_t* edge_keys) = 0;
  virtual absl::Status DoComputeIsoVertices(const GridView& grid, const int64_t* edge_keys,
                                            int64_t count, const IsoSurfaceParams& params,
                                            float* positions, float* normals,
                                            uint8_t* colors, uint8_t* observed) = 0;
};

// RefreshOccupancyIfStale: core/kernels/refresh_occupancy.h. MakeCpuBackend:
// core/cpu/cpu_backend.h.

}  // namespace plx

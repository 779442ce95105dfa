// Backend implementation on CPU threads: forwards to the plx::cpu kernel drivers.
#include "core/cpu/cpu_backend.h"

#include <memory>

#include "core/cpu/kernels_cpu.h"

namespace plx {
namespace {

class CpuBackend final : public Backend {
 public:
  CpuBackend(int num_threads, int nice) {
    if (num_threads > 0 || nice > 0) {
      own_pool_ = std::make_unique<cpu::ThreadPool>(num_threads, nice);
      ctx_.pool = own_pool_.get();
    }
  }

  std::string name() const override { return "cpu"; }
  int parallelism() const override { return ctx_.pool->num_threads(); }

  absl::Status DoRenderPixels(const GridView& grid, const CameraView& camera,
                              const int32_t* pixels, int64_t count, const RenderOptions& options,
                              float* color, float* depth, float* opacity,
                              float* median_depth) override {
    cpu::RenderPixels(ctx_, grid, camera, pixels, count, options, color, depth, opacity,
                      median_depth);
    return absl::OkStatus();
  }
  absl::Status DoMappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                        const TrainingRaysView& rays,
                                        const MappingBatchParams& params,
                                        MappingRayLoss* losses) override {
    cpu::MappingForwardBackward(ctx_, grid, grad, rays, params, losses);
    return absl::OkStatus();
  }
  absl::Status DoRmsPropStep(const GridView& grid, const GridWriteView& write,
                             const GridGradView& grad, const OptimizerStateView& state,
                             const RmsPropParams& params) override {
    cpu::RmsPropStep(ctx_, grid, write, grad, state, params);
    return absl::OkStatus();
  }
  absl::Status DoFuseDepth(const GridView& grid, const GridWriteView& write, int64_t first_vertex,
                           int64_t vertex_count, const TrainingFrameView* frames, int num_frames,
                           const FusionParams& params) override {
    cpu::FuseDepth(ctx_, grid, write, first_vertex, vertex_count, frames, num_frames, params);
    return absl::OkStatus();
  }
  absl::Status DoRefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                  const int64_t* active_blocks, int64_t count,
                                  float threshold) override {
    cpu::RefreshOccupancy(ctx_, grid, write, active_blocks, count, threshold);
    return absl::OkStatus();
  }
  absl::Status DoComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                      const int32_t* pixels, int64_t count,
                                      const TrackingParams& params,
                                      TrackingRayTerm* terms) override {
    cpu::ComputeTrackingTerms(ctx_, grid, frame, pixels, count, params, terms);
    return absl::OkStatus();
  }
  absl::Status DoReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                     TrackingLoss loss, float huber_k, const float scale[2],
                                     TrackingSums* sums) override {
    return cpu::ReduceTrackingTerms(ctx_, terms, count, loss, huber_k, scale, sums);
  }
  absl::Status DoResampleGrid(const GridView& target, const GridWriteView& target_write,
                              const GridView& source) override {
    cpu::ResampleGrid(ctx_, target, target_write, source);
    return absl::OkStatus();
  }
  absl::Status DoAddTvGradient(const GridView& grid, const GridGradView& grad,
                               int64_t first_vertex, int64_t vertex_count, float lambda_density,
                               float lambda_sh) override {
    cpu::AddTvGradient(ctx_, grid, grad, first_vertex, vertex_count, lambda_density, lambda_sh);
    return absl::OkStatus();
  }

 private:
  std::unique_ptr<cpu::ThreadPool> own_pool_;
  cpu::ExecContext ctx_;
};

}  // namespace

std::unique_ptr<Backend> MakeCpuBackend(int num_threads, int nice) {
  return std::make_unique<CpuBackend>(num_threads, nice);
}

}  // namespace plx

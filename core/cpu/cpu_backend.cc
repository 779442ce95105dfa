// Backend implementation on CPU threads: forwards to the plx::cpu kernel drivers.
#include "core/cpu/cpu_backend.h"

#include <memory>

#include "core/cpu/kernels_cpu.h"

namespace plx {
namespace {

class CpuBackend final : public Backend {
 public:
  explicit CpuBackend(int num_threads) {
    if (num_threads > 0) {
      own_pool_ = std::make_unique<cpu::ThreadPool>(num_threads);
      ctx_.pool = own_pool_.get();
    }
  }

  std::string name() const override { return "cpu"; }
  int parallelism() const override { return ctx_.pool->num_threads(); }

  void RenderPixels(const GridView& grid, const CameraView& camera, const int32_t* pixels,
                    int64_t count, const RenderOptions& options, float* color, float* depth,
                    float* opacity, float* median_depth) override {
    cpu::RenderPixels(ctx_, grid, camera, pixels, count, options, color, depth, opacity,
                      median_depth);
  }
  void MappingForwardBackward(const GridView& grid, const GridGradView& grad,
                              const TrainingRaysView& rays, const MappingBatchParams& params,
                              MappingRayLoss* losses) override {
    cpu::MappingForwardBackward(ctx_, grid, grad, rays, params, losses);
  }
  void RmsPropStep(const GridView& grid, const GridGradView& grad,
                   const OptimizerStateView& state, const RmsPropParams& params) override {
    cpu::RmsPropStep(ctx_, grid, grad, state, params);
  }
  void FuseDepth(const GridView& grid, int64_t first_vertex, int64_t vertex_count,
                 const TrainingFrameView* frames, int num_frames,
                 const FusionParams& params) override {
    cpu::FuseDepth(ctx_, grid, first_vertex, vertex_count, frames, num_frames, params);
  }
  void RefreshOccupancy(const GridView& grid, const int64_t* active_blocks, int64_t count,
                        float threshold) override {
    cpu::RefreshOccupancy(ctx_, grid, active_blocks, count, threshold);
  }
  void ComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                            const int32_t* pixels, int64_t count, const TrackingParams& params,
                            TrackingRayTerm* terms) override {
    cpu::ComputeTrackingTerms(ctx_, grid, frame, pixels, count, params, terms);
  }
  TrackingSums ReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count, TrackingLoss loss,
                                   float huber_k, const float scale[2]) override {
    return cpu::ReduceTrackingTerms(ctx_, terms, count, loss, huber_k, scale);
  }
  void ResampleGrid(const GridView& target, const GridView& source) override {
    cpu::ResampleGrid(ctx_, target, source);
  }
  void AddTvGradient(const GridView& grid, const GridGradView& grad, int64_t first_vertex,
                     int64_t vertex_count, float lambda_density, float lambda_sh) override {
    cpu::AddTvGradient(ctx_, grid, grad, first_vertex, vertex_count, lambda_density, lambda_sh);
  }

 private:
  std::unique_ptr<cpu::ThreadPool> own_pool_;
  cpu::ExecContext ctx_;
};

}  // namespace

std::unique_ptr<Backend> MakeCpuBackend(int num_threads) {
  return std::make_unique<CpuBackend>(num_threads);
}

}  // namespace plx

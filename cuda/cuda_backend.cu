// CudaBackend: forwards each Backend call to the plx::cuda kernel drivers on the backend's
// stream and synchronises before returning (callers read results right after). See
// cuda/cuda_backend.h for the memory residency rules.
#include "cuda/cuda_backend.h"

#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <unordered_map>

#include <cuda_runtime.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/common/unified_allocator.h"
#include "cuda/cuda_status.h"
#include "cuda/kernels_cuda.h"

namespace plx::cuda {
namespace {

// RMSProp work items per brick: 8 vertices per thread, so a batch's touched bricks fill the GPU
// (one thread per brick would leave it nearly idle and serialise 512 updates per thread).
constexpr int kRmsPropBrickSlices = 64;

// UnifiedVector hooks: CUDA managed memory, visible to the host and every device.
void* ManagedAllocate(size_t bytes, void*) {
  void* p = nullptr;
  if (cudaMallocManaged(&p, bytes, cudaMemAttachGlobal) != cudaSuccess) {
    (void)cudaGetLastError();  // out of memory is reported as std::bad_alloc, not left pending
    return nullptr;
  }
  return p;
}

void ManagedDeallocate(void* block, size_t, void*) {
  // cudaFree waits for the device; it fails harmlessly once the runtime is shutting down (static
  // destructors), when the memory goes back with the process anyway.
  (void)cudaFree(block);
}

// Copies where the pages are (device to device for a map's bricks): cloning a brick for a new
// map version never pulls it to the host. Synchronous, like the Backend calls.
void ManagedCopy(void* dst, const void* src, size_t bytes, void*) {
  if (cudaMemcpy(dst, src, bytes, cudaMemcpyDefault) != cudaSuccess) {
    (void)cudaGetLastError();
    std::memcpy(dst, src, bytes);  // managed memory is host-accessible: correct, only slower
  }
}

const UnifiedMemoryHooks kManagedHooks{&ManagedAllocate, &ManagedDeallocate, nullptr,
                                       "cuda-managed", &ManagedCopy};

void InstallManagedMemoryOnce() {
  static std::once_flag once;
  std::call_once(once, [] { InstallUnifiedMemoryHooks(&kManagedHooks); });
}

class CudaBackend final : public Backend {
 public:
  static absl::StatusOr<std::unique_ptr<Backend>> Create(int device) {
    const int devices = VisibleDeviceCount();
    if (device < 0 || device >= devices) {
      return absl::FailedPreconditionError(
          absl::StrCat("CUDA device ", device, " does not exist (", devices, " visible)"));
    }
    PLX_CUDA_RETURN_IF_ERROR(cudaSetDevice(device));
    cudaDeviceProp prop;
    PLX_CUDA_RETURN_IF_ERROR(cudaGetDeviceProperties(&prop, device));
    int concurrent_managed = 0, pageable = 0, pools = 0;
    PLX_CUDA_RETURN_IF_ERROR(
        cudaDeviceGetAttribute(&concurrent_managed, cudaDevAttrConcurrentManagedAccess, device));
    PLX_CUDA_RETURN_IF_ERROR(
        cudaDeviceGetAttribute(&pageable, cudaDevAttrPageableMemoryAccess, device));
    PLX_CUDA_RETURN_IF_ERROR(
        cudaDeviceGetAttribute(&pools, cudaDevAttrMemoryPoolsSupported, device));
    if (!concurrent_managed) {
      // Without it the host may not touch any managed memory while a kernel runs on the
      // device (Windows/WSL, some embedded boards): other workers' host code would fault.
      return absl::FailedPreconditionError(absl::StrCat(
          DescribeDevice(device),
          " lacks concurrent managed memory access, which the CUDA backend needs; use --backend "
          "cpu"));
    }
    if (!pools) {
      return absl::FailedPreconditionError(
          absl::StrCat(DescribeDevice(device), " has no stream-ordered memory pools"));
    }
    if (const cudaError_t image = ProbeKernelImage(); image != cudaSuccess) {
      (void)cudaGetLastError();
      return absl::FailedPreconditionError(absl::StrCat(
          "this binary has no CUDA code for ", DescribeDevice(device), " (",
          cudaGetErrorString(image), "); rebuild with -DPLX_CUDA_ARCHITECTURES=", prop.major,
          prop.minor));
    }
    cudaStream_t stream = nullptr;
    PLX_CUDA_RETURN_IF_ERROR(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
    InstallManagedMemoryOnce();
    return std::unique_ptr<Backend>(new CudaBackend(device, prop, pageable != 0, stream));
  }

  ~CudaBackend() override {
    (void)cudaSetDevice(device_);
    (void)cudaStreamSynchronize(stream_);
    (void)cudaStreamDestroy(stream_);
  }

  std::string name() const override { return name_; }
  int parallelism() const override { return sm_count_; }

  absl::Status DoRenderPixels(const GridView& grid, const CameraView& camera,
                              const int32_t* pixels, int64_t count, const RenderOptions& options,
                              float* color, float* depth, float* opacity,
                              float* median_depth) override {
    PLX_RETURN_IF_ERROR(Begin("RenderPixels"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(pixels, "pixels"));
    PLX_RETURN_IF_ERROR(Check(color, "color"));
    PLX_RETURN_IF_ERROR(Check(depth, "depth"));
    PLX_RETURN_IF_ERROR(Check(opacity, "opacity"));
    PLX_RETURN_IF_ERROR(Check(median_depth, "median_depth"));
    PrefetchGrid(grid);
    cuda::RenderPixels(ctx_, grid, camera, pixels, count, options, color, depth, opacity,
                       median_depth);
    return Finish();
  }

  absl::Status DoMappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                        const TrainingRaysView& rays,
                                        const MappingBatchParams& params,
                                        MappingRayLoss* losses) override {
    PLX_RETURN_IF_ERROR(Begin("MappingForwardBackward"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(CheckGrad(grad));
    PLX_RETURN_IF_ERROR(Check(rays.frames, "rays.frames"));
    PLX_RETURN_IF_ERROR(Check(rays.ray_frame, "rays.ray_frame"));
    PLX_RETURN_IF_ERROR(Check(rays.ray_pixel, "rays.ray_pixel"));
    PLX_RETURN_IF_ERROR(Check(losses, "losses"));
    PrefetchGrid(grid);
    PrefetchGrad(grid, grad);
    cuda::MappingForwardBackward(ctx_, grid, grad, rays, params, losses);
    return Finish();
  }

  absl::Status DoRmsPropStep(const GridView& grid, const GridWriteView& write,
                             const GridGradView& grad, const OptimizerStateView& state,
                             const RmsPropParams& params) override {
    PLX_RETURN_IF_ERROR(Begin("RmsPropStep"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(CheckWrite(write, "write"));
    PLX_RETURN_IF_ERROR(CheckGrad(grad));
    PLX_RETURN_IF_ERROR(Check(state.rms_density, "state.rms_density"));
    PLX_RETURN_IF_ERROR(Check(state.rms_sh, "state.rms_sh"));
    PrefetchGrid(grid);
    PrefetchGrad(grid, grad);
    const size_t n = static_cast<size_t>(grid.num_vertices());
    Prefetch(state.rms_density, n * sizeof(float));
    Prefetch(state.rms_sh, n * kShCoeffCount * sizeof(float));
    RmsPropParams sliced = params;
    sliced.brick_slices = kRmsPropBrickSlices;
    cuda::RmsPropStep(ctx_, grid, write, grad, state, sliced);
    return Finish();
  }

  absl::Status DoFuseDepth(const GridView& grid, const GridWriteView& write, int64_t first_vertex,
                           int64_t vertex_count, const TrainingFrameView* frames, int num_frames,
                           const FusionParams& params) override {
    PLX_RETURN_IF_ERROR(Begin("FuseDepth"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(CheckWrite(write, "write"));
    PLX_RETURN_IF_ERROR(Check(frames, "frames"));
    // Once per allocation round, so every frame's images are checked too.
    for (int f = 0; f < num_frames && frames != nullptr; ++f) {
      PLX_RETURN_IF_ERROR(Check(frames[f].color, "frames[].color"));
      PLX_RETURN_IF_ERROR(Check(frames[f].depth, "frames[].depth"));
    }
    PrefetchGrid(grid);
    cuda::FuseDepth(ctx_, grid, write, first_vertex, vertex_count, frames, num_frames, params);
    return Finish();
  }

  absl::Status DoRefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                  const int64_t* active_blocks, int64_t count,
                                  float threshold) override {
    PLX_RETURN_IF_ERROR(Begin("RefreshOccupancy"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(write.cell_bits, "write.cell_bits"));
    PLX_RETURN_IF_ERROR(Check(active_blocks, "active_blocks"));
    PrefetchGrid(grid);
    cuda::RefreshOccupancy(ctx_, grid, write, active_blocks, count, threshold);
    return Finish();
  }

  absl::Status DoComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                      const int32_t* pixels, int64_t count,
                                      const TrackingParams& params,
                                      TrackingRayTerm* terms) override {
    PLX_RETURN_IF_ERROR(Begin("ComputeTrackingTerms"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(frame.color, "frame.color"));
    PLX_RETURN_IF_ERROR(Check(frame.depth, "frame.depth"));
    PLX_RETURN_IF_ERROR(Check(pixels, "pixels"));
    PLX_RETURN_IF_ERROR(Check(terms, "terms"));
    PrefetchGrid(grid);
    cuda::ComputeTrackingTerms(ctx_, grid, frame, pixels, count, params, terms);
    return Finish();
  }

  absl::Status DoReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                     TrackingLoss loss, float huber_k, const float scale[2],
                                     TrackingSums* sums) override {
    PLX_RETURN_IF_ERROR(Begin("ReduceTrackingTerms"));
    PLX_RETURN_IF_ERROR(Check(terms, "terms"));
    PLX_RETURN_IF_ERROR(cuda::ReduceTrackingTerms(ctx_, terms, count, loss, huber_k, scale, sums));
    return Finish();
  }

  absl::Status DoResampleGrid(const GridView& target, const GridWriteView& target_write,
                              const GridView& source) override {
    PLX_RETURN_IF_ERROR(Begin("ResampleGrid"));
    PLX_RETURN_IF_ERROR(CheckGrid(target, "target"));
    PLX_RETURN_IF_ERROR(CheckWrite(target_write, "target_write"));
    PLX_RETURN_IF_ERROR(CheckGrid(source, "source"));
    PrefetchGrid(target);
    PrefetchGrid(source);
    cuda::ResampleGrid(ctx_, target, target_write, source);
    return Finish();
  }

  absl::Status DoAddTvGradient(const GridView& grid, const GridGradView& grad,
                               int64_t first_vertex, int64_t vertex_count, float lambda_density,
                               float lambda_sh) override {
    PLX_RETURN_IF_ERROR(Begin("AddTvGradient"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(CheckGrad(grad));
    PrefetchGrid(grid);
    PrefetchGrad(grid, grad);
    cuda::AddTvGradient(ctx_, grid, grad, first_vertex, vertex_count, lambda_density, lambda_sh);
    return Finish();
  }

  absl::Status DoCountIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                   const IsoSurfaceParams& params, uint8_t* triangles) override {
    PLX_RETURN_IF_ERROR(Begin("CountIsoTriangles"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(params.table, "params.table"));
    PLX_RETURN_IF_ERROR(Check(triangles, "triangles"));
    PrefetchGrid(grid);
    cuda::CountIsoTriangles(ctx_, grid, first_vertex, count, params, triangles);
    return Finish();
  }

  absl::Status DoEmitIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                  const IsoSurfaceParams& params, const int64_t* first_triangle,
                                  int64_t* edge_keys) override {
    PLX_RETURN_IF_ERROR(Begin("EmitIsoTriangles"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(params.table, "params.table"));
    PLX_RETURN_IF_ERROR(Check(first_triangle, "first_triangle"));
    PLX_RETURN_IF_ERROR(Check(edge_keys, "edge_keys"));
    PrefetchGrid(grid);
    cuda::EmitIsoTriangles(ctx_, grid, first_vertex, count, params, first_triangle, edge_keys);
    return Finish();
  }

  absl::Status DoComputeIsoVertices(const GridView& grid, const int64_t* edge_keys, int64_t count,
                                    const IsoSurfaceParams& params, float* positions,
                                    float* normals, uint8_t* colors, uint8_t* observed) override {
    PLX_RETURN_IF_ERROR(Begin("ComputeIsoVertices"));
    PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
    PLX_RETURN_IF_ERROR(Check(params.table, "params.table"));
    PLX_RETURN_IF_ERROR(Check(edge_keys, "edge_keys"));
    PLX_RETURN_IF_ERROR(Check(positions, "positions"));
    PLX_RETURN_IF_ERROR(Check(normals, "normals"));
    PLX_RETURN_IF_ERROR(Check(colors, "colors"));
    PLX_RETURN_IF_ERROR(Check(observed, "observed"));
    PrefetchGrid(grid);
    cuda::ComputeIsoVertices(ctx_, grid, edge_keys, count, params, positions, normals, colors,
                             observed);
    return Finish();
  }

 private:
  CudaBackend(int device, const cudaDeviceProp& prop, bool pageable_access, cudaStream_t stream)
      : device_(device),
        name_(absl::StrCat("cuda:", device, " ", prop.name)),
        sm_count_(prop.multiProcessorCount),
        pageable_access_(pageable_access),
        stream_(stream) {
    ctx_.stream = stream_;
  }

  // Every call: this thread's current device is ours (a worker thread may serve several), and
  // no error of an earlier, unrelated runtime call is left pending.
  absl::Status Begin(const char* method) {
    method_ = method;
    PLX_CUDA_RETURN_IF_ERROR(cudaSetDevice(device_));
    (void)cudaGetLastError();
    return absl::OkStatus();
  }

  // Launch errors show at once, execution errors at the synchronisation. Either fails this call
  // only; a sticky device error (an illegal address) fails every later call of this backend
  // too, each with the same message, while the other backends of the process keep working.
  absl::Status Finish() {
    if (const cudaError_t e = cudaGetLastError(); e != cudaSuccess) return Failed(e, "kernel launch");
    if (const cudaError_t e = cudaStreamSynchronize(stream_); e != cudaSuccess) {
      return Failed(e, "kernel execution");
    }
    return absl::OkStatus();
  }

  absl::Status Failed(cudaError_t error, const char* what) const {
    const std::string message = absl::StrFormat("%s::%s: %s failed: %s (%s)", name_, method_,
                                                what, cudaGetErrorName(error),
                                                cudaGetErrorString(error));
    if (error == cudaErrorMemoryAllocation) return absl::ResourceExhaustedError(message);
    return absl::InternalError(message);
  }

  // Views must point at memory this device can read (core/kernels/backend.h): managed memory
  // (UnifiedVector after the backend exists), its own device memory, or pinned host memory.
  // One driver lookup per pointer (about a microsecond), skipped when the device reads
  // pageable memory anyway. A violation fails the call with the argument's name instead of faulting
  // inside a kernel.
  absl::Status Check(const void* p, const char* what) const {
    if (p == nullptr || pageable_access_) return absl::OkStatus();
    cudaPointerAttributes attr;
    const cudaError_t e = cudaPointerGetAttributes(&attr, p);
    if (e != cudaSuccess) (void)cudaGetLastError();
    const bool readable =
        e == cudaSuccess &&
        (attr.type == cudaMemoryTypeManaged ||
         (attr.type == cudaMemoryTypeDevice && attr.device == device_) ||
         (attr.type == cudaMemoryTypeHost && attr.devicePointer != nullptr));
    if (readable) return absl::OkStatus();
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s::%s: `%s` (%p) is %s memory this GPU cannot read. Arrays passed to the CUDA backend "
        "must be UnifiedVector memory allocated after the backend was created "
        "(core/common/unified_allocator.h, core/kernels/backend.h).",
        name_, method_, what, p,
        e != cudaSuccess                    ? "unknown"
        : attr.type == cudaMemoryTypeDevice ? "another device's"
                                            : "ordinary host"));
  }

  // The brick tables are checked, not each brick: bricks come from the same UnifiedVector
  // hooks as the tables (core/grid/brick_storage.h).
  absl::Status CheckGrid(const GridView& g, const char* what) const {
    PLX_RETURN_IF_ERROR(Check(g.brick_density, absl::StrCat(what, ".brick_density").c_str()));
    PLX_RETURN_IF_ERROR(Check(g.brick_sh, absl::StrCat(what, ".brick_sh").c_str()));
    PLX_RETURN_IF_ERROR(Check(g.brick_slot, absl::StrCat(what, ".brick_slot").c_str()));
    PLX_RETURN_IF_ERROR(Check(g.block_cells, absl::StrCat(what, ".block_cells").c_str()));
    PLX_RETURN_IF_ERROR(Check(g.cell_bits, absl::StrCat(what, ".cell_bits").c_str()));
    return Check(g.brick_origin, absl::StrCat(what, ".brick_origin").c_str());
  }

  absl::Status CheckWrite(const GridWriteView& w, const char* what) const {
    PLX_RETURN_IF_ERROR(Check(w.brick_density, absl::StrCat(what, ".brick_density").c_str()));
    PLX_RETURN_IF_ERROR(Check(w.brick_sh, absl::StrCat(what, ".brick_sh").c_str()));
    return Check(w.cell_bits, absl::StrCat(what, ".cell_bits").c_str());
  }

  absl::Status CheckGrad(const GridGradView& g) const {
    PLX_RETURN_IF_ERROR(Check(g.density, "grad.density"));
    PLX_RETURN_IF_ERROR(Check(g.sh, "grad.sh"));
    PLX_RETURN_IF_ERROR(Check(g.touched, "grad.touched"));
    return Check(g.brick_touched, "grad.brick_touched");
  }

  // Managed pages move on demand (one fault per page group) or in bulk when prefetched. Each
  // large array is prefetched to the device once per (address, size): after the host grows a
  // grid (a new allocation, written by the host) the GPU pulls it over at copy speed instead
  // of fault by fault. Only a performance hint: errors are ignored.
  void Prefetch(const void* p, size_t bytes) {
    if (p == nullptr || bytes < (size_t{1} << 20)) return;
    auto [it, inserted] = prefetched_.try_emplace(p, bytes);
    if (!inserted && it->second == bytes) return;
    it->second = bytes;
    if (prefetched_.size() > 64) prefetched_.clear();  // addresses are reused after frees
    cudaMemLocation location{};
    location.type = cudaMemLocationTypeDevice;
    location.id = device_;
    if (cudaMemPrefetchAsync(p, bytes, location, 0, stream_) != cudaSuccess) {
      (void)cudaGetLastError();
    }
  }

  // Bricks are separate allocations (copy-on-write versions share them), too small and too
  // many to prefetch one by one: they migrate on first touch, and stay on the device while only
  // kernels write them (docs/GPU.md, "Copy-on-write versions").
  void PrefetchGrid(const GridView& g) {
    Prefetch(g.brick_slot, static_cast<size_t>(g.dims[0]) * g.dims[1] * g.dims[2] *
                               sizeof(int32_t));
  }

  void PrefetchGrad(const GridView& g, const GridGradView& grad) {
    const size_t n = static_cast<size_t>(g.num_vertices());
    Prefetch(grad.density, n * sizeof(float));
    Prefetch(grad.sh, n * kShCoeffCount * sizeof(float));
  }

  const int device_;
  const std::string name_;
  const int sm_count_;
  const bool pageable_access_;
  cudaStream_t stream_;
  ExecContext ctx_;
  const char* method_ = "";
  std::unordered_map<const void*, size_t> prefetched_;
};

}  // namespace

int VisibleDeviceCount() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();  // no driver / no device: not an error for the caller
    return 0;
  }
  return count;
}

std::string DescribeDevice(int device) {
  cudaDeviceProp prop;
  if (const cudaError_t e = cudaGetDeviceProperties(&prop, device); e != cudaSuccess) {
    (void)cudaGetLastError();
    return absl::StrCat("cuda:", device, " (unavailable: ", cudaGetErrorString(e), ")");
  }
  return absl::StrFormat("cuda:%d %s (sm_%d%d, %.1f GiB)", device, prop.name, prop.major,
                         prop.minor, static_cast<double>(prop.totalGlobalMem) / (1 << 30));
}

absl::StatusOr<std::unique_ptr<plx::Backend>> MakeCudaBackend(int device) {
  return CudaBackend::Create(device);
}

}  // namespace plx::cuda

// CUDA shell for core/kernels/tracking_impl.h (the CPU twin is core/cpu/tracking_cpu.cc), plus the
// CUDA reduction of the per-ray terms into the normal equations.
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/tracking_impl.h"

#include <algorithm>

#include "cuda/cuda_status.h"
#include "cuda/device_buffer.h"

namespace plx::cuda {
namespace {

constexpr int kReduceThreads = 256;
constexpr int kReduceWarps = kReduceThreads / 32;
// Partial sums per launch are capped so the block count, hence the summation order and the
// result, do not depend on the device.
constexpr int kMaxReduceBlocks = 256;
constexpr int kSumFields = static_cast<int>(sizeof(TrackingSums) / sizeof(double));
static_assert(sizeof(TrackingSums) == kSumFields * sizeof(double),
              "TrackingSums must be a plain array of doubles");

// Sums every thread's `local` over the block; thread 0 writes the total to `out`. Every thread
// of the block must call it (full-warp shuffles). Warps reduce by shuffles, then warp 0 adds
// the per-warp sums staged in shared memory.
__device__ void BlockReduceSums(const TrackingSums& local, TrackingSums* out) {
  __shared__ double warp_sums[kReduceWarps][kSumFields];
  const double* v = reinterpret_cast<const double*>(&local);
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
#pragma unroll
  for (int f = 0; f < kSumFields; ++f) {
    double x = v[f];
#pragma unroll
    for (int offset = 16; offset > 0; offset >>= 1) x += __shfl_down_sync(0xffffffffu, x, offset);
    if (lane == 0) warp_sums[warp][f] = x;
  }
  __syncthreads();
  if (warp != 0) return;
  double* o = reinterpret_cast<double*>(out);
#pragma unroll
  for (int f = 0; f < kSumFields; ++f) {
    double x = lane < kReduceWarps ? warp_sums[lane][f] : 0.0;
#pragma unroll
    for (int offset = 16; offset > 0; offset >>= 1) x += __shfl_down_sync(0xffffffffu, x, offset);
    if (lane == 0) o[f] = x;
  }
}

// Pass 1: each thread accumulates a grid-strided subset of rays with the shared per-ray math
// (AccumulateTrackingTerm, core/kernels/tracking_terms.h), then each block writes one partial.
__global__ void __launch_bounds__(kReduceThreads)
    AccumulateTermsKernel(const TrackingRayTerm* terms, int64_t count, TrackingLoss loss,
                          float huber_k, float color_scale, float depth_scale,
                          TrackingSums* partial) {
  TrackingSums local;
  local.Clear();
  const float scale[2] = {color_scale, depth_scale};
  const int64_t stride = static_cast<int64_t>(gridDim.x) * blockDim.x;
  for (int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < count;
       i += stride) {
    AccumulateTrackingTerm(terms[i], loss, huber_k, scale, &local);
  }
  BlockReduceSums(local, partial + blockIdx.x);
}

// Pass 2 (one block): adds the partials.
__global__ void __launch_bounds__(kReduceThreads)
    AddPartialsKernel(const TrackingSums* partial, int count, TrackingSums* out) {
  TrackingSums local;
  local.Clear();
  for (int i = threadIdx.x; i < count; i += blockDim.x) local.Add(partial[i]);
  BlockReduceSums(local, out);
}

}  // namespace

absl::Status Run(const ExecContext& ctx, const ReduceTrackingTermsArgs& args) {
  const int64_t count = args.count;
  args.sums->Clear();
  if (count <= 0) return absl::OkStatus();
  const int blocks = static_cast<int>(
      std::min<int64_t>(kMaxReduceBlocks, (count + kReduceThreads - 1) / kReduceThreads));
  // partial[0, blocks) per block, partial[blocks] the total.
  absl::StatusOr<DeviceBuffer<TrackingSums>> partial =
      DeviceBuffer<TrackingSums>::Create(static_cast<size_t>(blocks) + 1, ctx.stream);
  if (!partial.ok()) return partial.status();
  AccumulateTermsKernel<<<blocks, kReduceThreads, 0, ctx.stream>>>(
      args.terms, count, args.loss, args.huber_k, args.scale[0], args.scale[1], partial->data());
  PLX_CUDA_RETURN_IF_ERROR(cudaGetLastError());
  AddPartialsKernel<<<1, kReduceThreads, 0, ctx.stream>>>(partial->data(), blocks,
                                                         partial->data() + blocks);
  PLX_CUDA_RETURN_IF_ERROR(cudaGetLastError());
  PLX_CUDA_RETURN_IF_ERROR(cudaMemcpyAsync(args.sums, partial->data() + blocks,
                                           sizeof(TrackingSums), cudaMemcpyDeviceToHost,
                                           ctx.stream));
  PLX_CUDA_RETURN_IF_ERROR(cudaStreamSynchronize(ctx.stream));
  return absl::OkStatus();
}

cudaError_t ProbeKernelImage() {
  cudaFuncAttributes attributes;
  return cudaFuncGetAttributes(&attributes, AddPartialsKernel);
}

}  // namespace plx::cuda

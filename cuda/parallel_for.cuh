// The CUDA backend's ParallelFor: one thread per index, launched on the context's stream.
// core/kernels drivers call it unqualified; core/cpu/parallel_for.h is the CPU twin.
#pragma once

#include <cstdint>

#include <cuda_runtime.h>

namespace plx::cuda {

struct ExecContext {
  cudaStream_t stream = nullptr;
};

inline constexpr int kThreadsPerBlock = 128;

template <typename F>
__global__ void ParallelForKernel(int64_t n, F f) {
  const int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) f(i);
}

template <typename F>
void ParallelFor(const ExecContext& ctx, int64_t n, F f) {
  if (n <= 0) return;
  const int64_t blocks = (n + kThreadsPerBlock - 1) / kThreadsPerBlock;
  ParallelForKernel<<<static_cast<unsigned int>(blocks), kThreadsPerBlock, 0, ctx.stream>>>(n, f);
}

}  // namespace plx::cuda

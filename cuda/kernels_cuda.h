// The CUDA backend's kernel drivers: the same list as the CPU backend
// (core/kernels/kernel_declarations.inc), compiled by nvcc from the same *_impl.h sources.
#pragma once

#include "absl/status/status.h"
#include "core/kernels/kernel_args.h"
#include "cuda/parallel_for.cuh"

namespace plx::cuda {
#include "core/kernels/kernel_declarations.inc"
}  // namespace plx::cuda

namespace plx::cuda {
// cudaSuccess when this binary holds code the current device can run (cuda/tracking_cuda.cu),
// e.g. cudaErrorNoKernelImageForDevice when it was built for other architectures.
cudaError_t ProbeKernelImage();
}  // namespace plx::cuda

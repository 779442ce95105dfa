// The CUDA backend (DESIGN.md §3): the kernel drivers of core/kernels compiled by nvcc, behind
// the Backend interface. Plain C++ header (no CUDA types) so app/make_backend.cc, compiled by
// the host compiler, can include it.
//
// Memory residency: kernels read and write the host owners' arrays in place. Creating the first
// CudaBackend installs cudaMallocManaged/cudaFree as the UnifiedVector hooks
// (core/common/unified_allocator.h), so grids, optimiser state, training frames, images and
// tracking/render buffers allocated from then on are CUDA managed memory, which pages migrate
// on demand between host and GPU. Arrays allocated before (e.g. a map loaded before the backend
// was made) are ordinary host memory: a call that passes them fails (INVALID_ARGUMENT) with a
// message naming the argument unless the device can read pageable memory (HMM / coherent
// systems).
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "core/kernels/backend.h"

namespace plx::cuda {

// CUDA devices this process can use; 0 when there is no driver or device (never aborts).
int VisibleDeviceCount();

// "cuda:0 NVIDIA H100 80GB HBM3 (sm_90, 79.1 GiB)"; "cuda:N (unavailable: reason)" on error.
std::string DescribeDevice(int device);

// A backend on `device` with its own stream. Every call runs on that stream and synchronises
// before it returns, so host code may read the results right away. FailedPrecondition when the
// device does not exist, lacks concurrent managed access, or this binary has no code for its
// architecture (rebuild with -DPLX_CUDA_ARCHITECTURES=<its sm>).
absl::StatusOr<std::unique_ptr<plx::Backend>> MakeCudaBackend(int device);

}  // namespace plx::cuda

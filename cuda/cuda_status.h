// CUDA runtime errors as absl::Status: every CUDA call of the project returns one, so a failed
// launch or allocation fails one request instead of the process (core/kernels/backend.h).
#pragma once

#include <cuda_runtime.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace plx::cuda {

// Ok for cudaSuccess, else an error naming the call site, the expression and CUDA's text.
// Out-of-memory maps to ResourceExhausted, no device / no driver to FailedPrecondition.
inline absl::Status CudaStatus(cudaError_t error, const char* expr, const char* file, int line) {
  if (error == cudaSuccess) return absl::OkStatus();
  const std::string message = absl::StrCat(file, ":", line, ": ", expr, " failed: ",
                                           cudaGetErrorName(error), " (",
                                           cudaGetErrorString(error), ")");
  switch (error) {
    case cudaErrorMemoryAllocation:
      return absl::ResourceExhaustedError(message);
    case cudaErrorNoDevice:
    case cudaErrorInsufficientDriver:
    case cudaErrorInvalidDevice:
    case cudaErrorDevicesUnavailable:
      return absl::FailedPreconditionError(message);
    default:
      return absl::InternalError(message);
  }
}

}  // namespace plx::cuda

// Returns an absl::Status from the enclosing function when the CUDA call fails.
#define PLX_CUDA_RETURN_IF_ERROR(expr)                                                 \
  do {                                                                                 \
    const cudaError_t plx_cuda_error_ = (expr);                                        \
    if (plx_cuda_error_ != cudaSuccess) {                                              \
      return ::plx::cuda::CudaStatus(plx_cuda_error_, #expr, __FILE__, __LINE__);      \
    }                                                                                  \
  } while (false)

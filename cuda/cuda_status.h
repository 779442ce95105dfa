// CUDA runtime errors as absl::Status (for code that can return one) and a checked call for
// void contexts (Backend methods, destructors' callers), which aborts with the location and
// CUDA's message: a failed launch or a sticky device error cannot be recovered from there.
#pragma once

#include <cstdio>
#include <cstdlib>

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

// Prints the error and aborts (used where no Status can be returned).
[[noreturn]] inline void CudaFatal(cudaError_t error, const char* expr, const char* file,
                                   int line) {
  std::fprintf(stderr, "plenoxd: fatal CUDA error at %s:%d: %s failed: %s (%s)\n", file, line,
               expr, cudaGetErrorName(error), cudaGetErrorString(error));
  std::fflush(stderr);
  std::abort();
}

// Prints a failed status and aborts (void contexts that got a Status from a helper).
[[noreturn]] inline void FatalStatus(const absl::Status& status) {
  std::fprintf(stderr, "plenoxd: fatal CUDA error: %s\n", status.ToString().c_str());
  std::fflush(stderr);
  std::abort();
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

// Aborts with the location and CUDA's message when the call fails (void contexts).
#define PLX_CUDA_CHECK(expr)                                                           \
  do {                                                                                 \
    const cudaError_t plx_cuda_error_ = (expr);                                        \
    if (plx_cuda_error_ != cudaSuccess) {                                              \
      ::plx::cuda::CudaFatal(plx_cuda_error_, #expr, __FILE__, __LINE__);              \
    }                                                                                  \
  } while (false)

// Choosing the compute backend at run time (--backend cpu|cuda|auto, --gpus). This is the one
// seam between the programs (clients/, server/) and cuda/: it is compiled in every build (as
// plain C++), and in a build without CUDA asking for "cuda" is a clear error, "auto" is the CPU.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/kernels/backend.h"

namespace plx {

enum class BackendKind { kCpu, kCuda, kAuto };

// "cpu", "cuda" or "auto"; InvalidArgument naming `flag` otherwise.
absl::StatusOr<BackendKind> ParseBackendKind(absl::string_view text,
                                             absl::string_view flag = "--backend");

// Whether this binary was built with the CUDA backend.
bool BuiltWithCuda();

// CUDA devices the process can use (0 without CUDA support, driver or device).
int CudaDeviceCount();

// A description of CUDA device `device` for logs, health and metrics, e.g.
// "cuda:0 NVIDIA H100 80GB HBM3 (sm_90, 79.1 GiB)"; "cpu (N threads)" style names come from
// Backend::name().
std::string CudaDeviceName(int device);

// kCpu: the CPU backend with `cpu_threads` (<= 0: all cores). kCuda: CUDA device
// `cuda_device` (FailedPrecondition when the build has no CUDA or the device does not exist,
// naming the reason). kAuto: CUDA device `cuda_device` when one exists, else the CPU.
absl::StatusOr<std::unique_ptr<Backend>> MakeBackend(BackendKind kind, int cuda_device = 0,
                                                     int cpu_threads = 0);

// "0,2" -> {0, 2}; "all" -> every visible device; InvalidArgument for bad or repeated ids or
// ids not below CudaDeviceCount().
absl::StatusOr<std::vector<int>> ParseGpuList(absl::string_view text);

}  // namespace plx

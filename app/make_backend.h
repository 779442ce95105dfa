// Choosing the compute backend at run time (--backend cpu|cuda|auto, --gpus) for the programs
// (server/, clients/). This is their one seam to cuda/: it is plain C++ compiled in every build;
// in a build without CUDA asking for "cuda" is a clear error and "auto" is the CPU.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/kernels/backend.h"

namespace plx {

enum class BackendKind { kCpu, kCuda, kAuto };

// "cpu", "cuda" or "auto"; InvalidArgument naming `flag` otherwise.
absl::StatusOr<BackendKind> ParseBackendKind(absl::string_view text,
                                             absl::string_view flag = "--backend");

// The inverse of ParseBackendKind: "cpu", "cuda" or "auto".
const char* BackendKindText(BackendKind kind);

// --gpus selects CUDA devices, so it makes no sense with --backend cpu: InvalidArgument then.
// One check for every program that takes both flags (plenoxd's main and Daemon::Start).
absl::Status CheckGpusApply(BackendKind kind, bool gpus_given);

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

// How in-process SLAM shares `cores` CPU cores when the user does not choose (plenox slam
// without --threads): the tracker's pool and the mapper's each on their own half (the tracker
// gets the odd core), at least one thread each. With two pools over every core the mapper's
// threads and the tracker's took turns on each core: a frame's map tracking took ~2.5x as long
// at equal priority, and with the mapper niced, integration starved and keyframes fell behind
// (docs/BENCHMARKS.md, issue 21's speed section).
struct SlamCpuThreads {
  int tracking = 1;
  int mapping = 1;
};
SlamCpuThreads SplitCoresForSlam(int cores);

// "0,2" -> {0, 2}; "all" -> every visible device; InvalidArgument for bad or repeated ids or
// ids not below CudaDeviceCount().
absl::StatusOr<std::vector<int>> ParseGpuList(absl::string_view text);

}  // namespace plx

#include "app/make_backend.h"

#include <algorithm>
#include <set>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "core/cpu/cpu_backend.h"

#ifdef PLX_HAVE_CUDA
#include "cuda/cuda_backend.h"
#endif

namespace plx {

absl::StatusOr<BackendKind> ParseBackendKind(absl::string_view text, absl::string_view flag) {
  if (text == "cpu") return BackendKind::kCpu;
  if (text == "cuda") return BackendKind::kCuda;
  if (text == "auto") return BackendKind::kAuto;
  return absl::InvalidArgumentError(
      absl::StrCat(flag, " must be cpu, cuda or auto, got \"", text, "\""));
}

const char* BackendKindText(BackendKind kind) {
  switch (kind) {
    case BackendKind::kCpu: return "cpu";
    case BackendKind::kCuda: return "cuda";
    case BackendKind::kAuto: return "auto";
  }
  return "auto";
}

absl::Status CheckGpusApply(BackendKind kind, bool gpus_given) {
  if (kind == BackendKind::kCpu && gpus_given) {
    return absl::InvalidArgumentError("--gpus only applies with --backend cuda or auto");
  }
  return absl::OkStatus();
}

bool BuiltWithCuda() {
#ifdef PLX_HAVE_CUDA
  return true;
#else
  return false;
#endif
}

int CudaDeviceCount() {
#ifdef PLX_HAVE_CUDA
  return cuda::VisibleDeviceCount();
#else
  return 0;
#endif
}

std::string CudaDeviceName(int device) {
#ifdef PLX_HAVE_CUDA
  return cuda::DescribeDevice(device);
#else
  return absl::StrCat("cuda:", device, " (not built)");
#endif
}

SlamCpuThreads SplitCoresForSlam(int cores) {
  SlamCpuThreads out;
  out.mapping = std::max(1, cores / 2);
  out.tracking = std::max(1, cores - out.mapping);
  return out;
}

absl::StatusOr<std::unique_ptr<Backend>> MakeBackend(BackendKind kind, int cuda_device,
                                                     int cpu_threads) {
  if (kind == BackendKind::kCpu) return MakeCpuBackend(cpu_threads);
  const int devices = CudaDeviceCount();
  if (kind == BackendKind::kAuto && devices == 0) return MakeCpuBackend(cpu_threads);
  if (!BuiltWithCuda()) {
    return absl::FailedPreconditionError(
        "this build has no CUDA backend (configure with nvcc installed and -DPLX_WITH_CUDA=ON); "
        "use --backend cpu");
  }
  if (cuda_device < 0 || cuda_device >= devices) {
    return absl::FailedPreconditionError(
        devices == 0 ? std::string("no CUDA device is visible (no NVIDIA GPU, driver, or "
                                   "CUDA_VISIBLE_DEVICES hides them); use --backend cpu or auto")
                     : absl::StrCat("CUDA device ", cuda_device, " does not exist (", devices,
                                    " visible)"));
  }
#ifdef PLX_HAVE_CUDA
  return cuda::MakeCudaBackend(cuda_device);
#else
  return absl::InternalError("unreachable");
#endif
}

absl::StatusOr<std::vector<int>> ParseGpuList(absl::string_view text) {
  const int devices = CudaDeviceCount();
  std::vector<int> ids;
  if (text == "all") {
    for (int i = 0; i < devices; ++i) ids.push_back(i);
    return ids;
  }
  std::set<int> seen;
  for (absl::string_view part : absl::StrSplit(text, ',')) {
    part = absl::StripAsciiWhitespace(part);
    int id = -1;
    if (!absl::SimpleAtoi(part, &id) || id < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("--gpus: expected \"all\" or device ids like 0,1; got \"", text, "\""));
    }
    if (!seen.insert(id).second) {
      return absl::InvalidArgumentError(absl::StrCat("--gpus: device ", id, " is listed twice"));
    }
    if (id >= devices) {
      return absl::InvalidArgumentError(absl::StrCat("--gpus: device ", id, " does not exist (",
                                                     devices, " CUDA devices visible)"));
    }
    ids.push_back(id);
  }
  return ids;
}

}  // namespace plx

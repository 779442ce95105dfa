// CudaBackend: forwards each Backend call to its plx::cuda kernel driver on the backend's
// stream and synchronises before returning (callers read results right after). What it checks
// and prefetches comes from the kernel's argument struct (core/kernels/kernel_args.h). See
// cuda/cuda_backend.h for the memory residency rules.
#include "cuda/cuda_backend.h"

#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <unordered_map>
#include <variant>

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

 private:
  absl::Status Launch(const KernelArgs& call) override {
    return std::visit([this](const auto& args) { return LaunchOnDevice(args); }, call);
  }

  // Every kernel: the arrays its argument struct lists checked for residency, the large ones
  // prefetched, then its driver on our stream.
  template <typename Args>
  absl::Status LaunchOnDevice(Args args) {
    PLX_RETURN_IF_ERROR(Begin(Args::kName));
    absl::Status readable;
    ForEachBuffer(args, [&](const KernelBuffer& b) {
      if (readable.ok() && !b.host) readable.Update(CheckReadable(b));
    });
    PLX_RETURN_IF_ERROR(readable);
    ForEachBuffer(args, [&](const KernelBuffer& b) {
      if (b.prefetch) Prefetch(b.data, b.bytes());
    });
    TuneForDevice(args);
    PLX_RETURN_IF_ERROR(CallDriver([&] { return cuda::Run(ctx_, args); }));
    return Finish();
  }

  // What a GPU wants of a kernel that the CPU does not; nothing for most.
  template <typename Args>
  static void TuneForDevice(Args&) {}
  static void TuneForDevice(RmsPropStepArgs& args) {
    args.params.brick_slices = kRmsPropBrickSlices;
  }

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
    if (const cudaError_t e = cudaGetLastError(); e != cudaSuccess) {
      return Failed(e, "kernel launch");
    }
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
  // pageable memory anyway. A violation fails the call with the argument's name instead of
  // faulting inside a kernel. Null is Backend's to check (required arrays are never null here).
  absl::Status CheckReadable(const KernelBuffer& buffer) const {
    const void* p = buffer.data;
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
        name_, method_, ArgumentLabel(buffer.group, buffer.name), p,
        e != cudaSuccess                    ? "unknown"
        : attr.type == cudaMemoryTypeDevice ? "another device's"
                                            : "ordinary host"));
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

// DeviceBuffer<T>: move-only owner of `size` elements of device memory, allocated and freed in
// stream order on its stream (cudaMallocAsync / cudaFreeAsync), with asynchronous copies on
// the same stream. For scratch space and results the host never touches in place (reduction
// partials); data shared with host code lives in UnifiedVector (core/common/unified_allocator.h).
#pragma once

#include <cstddef>
#include <type_traits>
#include <utility>

#include <cuda_runtime.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cuda/cuda_status.h"

namespace plx::cuda {

template <typename T>
class DeviceBuffer {
  static_assert(std::is_trivially_copyable_v<T>, "device buffers hold plain data");

 public:
  DeviceBuffer() = default;

  // `size` elements (uninitialised) on `stream`; the memory is usable by work queued on it.
  static absl::StatusOr<DeviceBuffer> Create(size_t size, cudaStream_t stream) {
    DeviceBuffer b;
    b.stream_ = stream;
    if (size > 0) {
      void* p = nullptr;
      PLX_CUDA_RETURN_IF_ERROR(cudaMallocAsync(&p, size * sizeof(T), stream));
      b.data_ = static_cast<T*>(p);
      b.size_ = size;
    }
    return b;
  }

  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept { *this = std::move(o); }
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      Reset();
      data_ = std::exchange(o.data_, nullptr);
      size_ = std::exchange(o.size_, 0);
      stream_ = o.stream_;
    }
    return *this;
  }
  ~DeviceBuffer() { Reset(); }

  T* data() { return data_; }
  const T* data() const { return data_; }
  size_t size() const { return size_; }
  size_t bytes() const { return size_ * sizeof(T); }
  bool empty() const { return size_ == 0; }
  cudaStream_t stream() const { return stream_; }

  // Queues a copy of `count` elements from host `src` into elements [offset, offset + count).
  // Pageable `src` makes the call return only once the data is staged, pinned memory does not.
  absl::Status CopyFromHostAsync(const T* src, size_t count, size_t offset = 0) {
    if (offset + count > size_) return absl::OutOfRangeError("DeviceBuffer: copy past the end");
    if (count == 0) return absl::OkStatus();
    PLX_CUDA_RETURN_IF_ERROR(cudaMemcpyAsync(data_ + offset, src, count * sizeof(T),
                                             cudaMemcpyHostToDevice, stream_));
    return absl::OkStatus();
  }

  // Queues a copy of elements [offset, offset + count) into host `dst`; `dst` is valid after
  // the stream is synchronised.
  absl::Status CopyToHostAsync(T* dst, size_t count, size_t offset = 0) const {
    if (offset + count > size_) return absl::OutOfRangeError("DeviceBuffer: copy past the end");
    if (count == 0) return absl::OkStatus();
    PLX_CUDA_RETURN_IF_ERROR(cudaMemcpyAsync(dst, data_ + offset, count * sizeof(T),
                                             cudaMemcpyDeviceToHost, stream_));
    return absl::OkStatus();
  }

  // Queues zero bytes over the whole buffer.
  absl::Status ZeroAsync() {
    if (size_ == 0) return absl::OkStatus();
    PLX_CUDA_RETURN_IF_ERROR(cudaMemsetAsync(data_, 0, bytes(), stream_));
    return absl::OkStatus();
  }

 private:
  void Reset() {
    // Stream-ordered: the memory is released after the work already queued on the stream.
    if (data_ != nullptr) (void)cudaFreeAsync(data_, stream_);
    data_ = nullptr;
    size_ = 0;
  }

  T* data_ = nullptr;
  size_t size_ = 0;
  cudaStream_t stream_ = nullptr;
};

}  // namespace plx::cuda

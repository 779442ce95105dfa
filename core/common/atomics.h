// Atomic float add for gradient scatter, one spelling for both backends (DESIGN.md §3.4).
#pragma once

#include <cstdint>

#include "core/common/host_device.h"

#if !defined(__CUDA_ARCH__)
#include <atomic>
#endif

namespace plx {

template <typename T>
PLX_HD void AtomicAdd(T* address, T value) {
#if defined(__CUDA_ARCH__)
  atomicAdd(address, value);
#else
  std::atomic_ref<T>(*address).fetch_add(value, std::memory_order_relaxed);
#endif
}

// Sets bits of a 64-bit word.
PLX_HD void AtomicOr(uint64_t* address, uint64_t bits) {
#if defined(__CUDA_ARCH__)
  atomicOr(reinterpret_cast<unsigned long long*>(address), static_cast<unsigned long long>(bits));
#else
  std::atomic_ref<uint64_t>(*address).fetch_or(bits, std::memory_order_relaxed);
#endif
}

// Marks a flag; concurrent writers all store 1, so relaxed ordering is enough.
PLX_HD void AtomicSetFlag(uint8_t* flag) {
#if defined(__CUDA_ARCH__)
  *reinterpret_cast<volatile uint8_t*>(flag) = 1;
#else
  std::atomic_ref<uint8_t>(*flag).store(1, std::memory_order_relaxed);
#endif
}

}  // namespace plx

// Memory that every backend can read: the large arrays kernels touch (grid, gradients,
// optimiser state, training frames and rays, images, tracking and render buffers) are
// UnifiedVector<T> rather than std::vector<T>. Allocation goes through process-wide hooks:
// by default aligned new/delete, blocks of 2 MB and more on transparent huge pages where the
// kernel allows it (the CPU backend sees ordinary memory); the CUDA backend installs
// cudaMallocManaged/cudaFree when its first instance is created, so data allocated from then
// on is readable and writable by host and GPU alike.
//
// Blocks remember which hooks made them (a small header in front of the data), so a block that
// was allocated before other hooks were installed is still freed by its own deallocator: mixing
// is safe. Hooks must outlive every block they allocated (use objects with static storage).
#pragma once

#include <cstddef>
#include <limits>
#include <new>
#include <vector>

namespace plx {

struct UnifiedMemoryHooks {
  // Returns `bytes` of memory aligned to at least kUnifiedAlignment, or null on failure.
  void* (*allocate)(size_t bytes, void* context) = nullptr;
  // Frees a block `allocate` returned (with the same byte count).
  void (*deallocate)(void* block, size_t bytes, void* context) = nullptr;
  void* context = nullptr;
  const char* name = "";
  // Copies `bytes` between two blocks of these hooks where the data lives (CUDA: on the device,
  // without migrating pages to the host); null: memcpy.
  void (*copy)(void* dst, const void* src, size_t bytes, void* context) = nullptr;
};

// Alignment of every UnifiedVector's data (a cache line; also the header size).
inline constexpr size_t kUnifiedAlignment = 64;

// The hooks new allocations use now, and the built-in ones (aligned operator new/delete).
const UnifiedMemoryHooks& CurrentUnifiedMemoryHooks();
const UnifiedMemoryHooks& DefaultUnifiedMemoryHooks();

// Installs `hooks` for allocations from now on (null: back to the default) and returns the
// previous ones. `hooks` must stay alive while any block it allocated does.
const UnifiedMemoryHooks* InstallUnifiedMemoryHooks(const UnifiedMemoryHooks* hooks);

// Raw interface behind UnifiedAllocator: throws std::bad_alloc when the hooks fail.
void* UnifiedAllocate(size_t bytes);
void UnifiedDeallocate(void* data, size_t bytes) noexcept;

// The hooks that allocated `data` (a pointer UnifiedAllocate returned).
const UnifiedMemoryHooks& UnifiedBlockHooks(const void* data);

// Copies `bytes` from `src` to `dst` (any memory the current hooks' copy handles: the CUDA
// hooks copy between any host, managed or device addresses) where the data lives; copy-on-write
// map versions clone bricks and indexes with it.
void UnifiedCopy(void* dst, const void* src, size_t bytes);

template <typename T>
class UnifiedAllocator {
 public:
  using value_type = T;
  static_assert(alignof(T) <= kUnifiedAlignment, "over-aligned type");

  UnifiedAllocator() noexcept = default;
  template <typename U>
  UnifiedAllocator(const UnifiedAllocator<U>&) noexcept {}  // NOLINT: allocator rebinding

  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    return static_cast<T*>(UnifiedAllocate(n * sizeof(T)));
  }
  void deallocate(T* p, size_t n) noexcept { UnifiedDeallocate(p, n * sizeof(T)); }

  // Stateless: any instance frees any block (each block knows its deallocator).
  template <typename U>
  bool operator==(const UnifiedAllocator<U>&) const noexcept { return true; }
  template <typename U>
  bool operator!=(const UnifiedAllocator<U>&) const noexcept { return false; }
};

template <typename T>
using UnifiedVector = std::vector<T, UnifiedAllocator<T>>;

}  // namespace plx

#include "core/common/unified_allocator.h"

#include <sys/mman.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>

namespace plx {
namespace {

// Blocks of at least a huge page are aligned to one and advised to be backed by huge pages.
// The grid, its optimiser state and each copy-on-write clone are hundreds of megabytes of fresh
// memory (glibc maps blocks that large anew each time and unmaps them when freed): touched for
// the first time, 4 KiB pages cost a page fault each, which in a virtual machine made most of
// keyframe 0's integration (docs/BENCHMARKS.md). With transparent huge pages "never" the advice
// does nothing.
constexpr size_t kHugePageBytes = size_t{2} << 20;

void* DefaultAllocate(size_t bytes, void*) {
  if (bytes >= kHugePageBytes) {
    if (bytes > SIZE_MAX - kHugePageBytes) return nullptr;  // no size rounds up to it
    const size_t rounded = (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
    void* block = std::aligned_alloc(kHugePageBytes, rounded);
    if (block != nullptr) madvise(block, rounded, MADV_HUGEPAGE);  // advice: failure is harmless
    return block;
  }
  return ::operator new(bytes, std::align_val_t{kUnifiedAlignment}, std::nothrow);
}

// `bytes` is what DefaultAllocate was asked for, so the block is freed the way it was made.
void DefaultDeallocate(void* block, size_t bytes, void*) {
  if (bytes >= kHugePageBytes) {
    std::free(block);
    return;
  }
  ::operator delete(block, std::align_val_t{kUnifiedAlignment});
}

constexpr UnifiedMemoryHooks kDefaultHooks{&DefaultAllocate, &DefaultDeallocate, nullptr,
                                           "host"};

std::atomic<const UnifiedMemoryHooks*>& CurrentHooks() {
  static std::atomic<const UnifiedMemoryHooks*> hooks{&kDefaultHooks};
  return hooks;
}

// Every block starts with this header; the data follows at kUnifiedAlignment.
struct BlockHeader {
  const UnifiedMemoryHooks* hooks;
};
static_assert(sizeof(BlockHeader) <= kUnifiedAlignment);

BlockHeader* HeaderOf(const void* data) {
  return reinterpret_cast<BlockHeader*>(
      const_cast<char*>(static_cast<const char*>(data) - kUnifiedAlignment));
}

}  // namespace

const UnifiedMemoryHooks& CurrentUnifiedMemoryHooks() {
  return *CurrentHooks().load(std::memory_order_acquire);
}

const UnifiedMemoryHooks& DefaultUnifiedMemoryHooks() { return kDefaultHooks; }

const UnifiedMemoryHooks* InstallUnifiedMemoryHooks(const UnifiedMemoryHooks* hooks) {
  return CurrentHooks().exchange(hooks != nullptr ? hooks : &kDefaultHooks,
                                 std::memory_order_acq_rel);
}

void* UnifiedAllocate(size_t bytes) {
  if (bytes > SIZE_MAX - kUnifiedAlignment) throw std::bad_alloc();
  const UnifiedMemoryHooks* hooks = CurrentHooks().load(std::memory_order_acquire);
  void* block = hooks->allocate(bytes + kUnifiedAlignment, hooks->context);
  if (block == nullptr) throw std::bad_alloc();
  static_cast<BlockHeader*>(block)->hooks = hooks;
  return static_cast<char*>(block) + kUnifiedAlignment;
}

void UnifiedDeallocate(void* data, size_t bytes) noexcept {
  if (data == nullptr) return;
  BlockHeader* header = HeaderOf(data);
  const UnifiedMemoryHooks* hooks = header->hooks;
  hooks->deallocate(header, bytes + kUnifiedAlignment, hooks->context);
}

const UnifiedMemoryHooks& UnifiedBlockHooks(const void* data) { return *HeaderOf(data)->hooks; }

void UnifiedCopy(void* dst, const void* src, size_t bytes) {
  if (bytes == 0) return;
  const UnifiedMemoryHooks* hooks = CurrentHooks().load(std::memory_order_acquire);
  if (hooks->copy != nullptr) {
    hooks->copy(dst, src, bytes, hooks->context);
  } else {
    std::memcpy(dst, src, bytes);
  }
}

}  // namespace plx

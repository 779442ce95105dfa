#include "core/common/unified_allocator.h"

#include <atomic>
#include <cstdint>
#include <cstring>

namespace plx {
namespace {

void* DefaultAllocate(size_t bytes, void*) {
  return ::operator new(bytes, std::align_val_t{kUnifiedAlignment}, std::nothrow);
}

void DefaultDeallocate(void* block, size_t, void*) {
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

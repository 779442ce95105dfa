#include "core/common/unified_allocator.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>

namespace plx {
namespace {

// Hooks that count their calls and forward to the default (aligned new/delete) hooks.
struct CountingHooks {
  UnifiedMemoryHooks hooks;
  int allocations = 0;
  int deallocations = 0;

  explicit CountingHooks(const char* name) {
    hooks.allocate = [](size_t bytes, void* self) -> void* {
      ++static_cast<CountingHooks*>(self)->allocations;
      const UnifiedMemoryHooks& d = DefaultUnifiedMemoryHooks();
      return d.allocate(bytes, d.context);
    };
    hooks.deallocate = [](void* block, size_t bytes, void* self) {
      ++static_cast<CountingHooks*>(self)->deallocations;
      const UnifiedMemoryHooks& d = DefaultUnifiedMemoryHooks();
      d.deallocate(block, bytes, d.context);
    };
    hooks.context = this;
    hooks.name = name;
  }
};

// Restores whatever hooks were installed before the test (the default in this binary).
class UnifiedAllocatorTest : public ::testing::Test {
 protected:
  void SetUp() override { previous_ = InstallUnifiedMemoryHooks(nullptr); }
  void TearDown() override { InstallUnifiedMemoryHooks(previous_); }
  const UnifiedMemoryHooks* previous_ = nullptr;
};

TEST_F(UnifiedAllocatorTest, DefaultHooksGiveAlignedHostMemory) {
  EXPECT_EQ(&CurrentUnifiedMemoryHooks(), &DefaultUnifiedMemoryHooks());
  UnifiedVector<float> v(1000);
  std::iota(v.begin(), v.end(), 0.0f);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(v.data()) % kUnifiedAlignment, 0u);
  EXPECT_EQ(&UnifiedBlockHooks(v.data()), &DefaultUnifiedMemoryHooks());
  EXPECT_FLOAT_EQ(v[999], 999.0f);
}

// The pitfall the block header exists for: a block allocated before other hooks were installed
// must go back to the allocator that made it, and new blocks to the new hooks.
TEST_F(UnifiedAllocatorTest, BlocksAreFreedByTheHooksThatAllocatedThem) {
  static CountingHooks first("first"), second("second");
  first.allocations = first.deallocations = second.allocations = second.deallocations = 0;

  auto* made_by_default = new UnifiedVector<int>(100, 7);  // default hooks
  InstallUnifiedMemoryHooks(&first.hooks);
  auto* made_by_first = new UnifiedVector<int>(200, 8);
  EXPECT_EQ(first.allocations, 1);
  EXPECT_EQ(&UnifiedBlockHooks(made_by_first->data()), &first.hooks);

  InstallUnifiedMemoryHooks(&second.hooks);
  delete made_by_default;  // default deallocator: neither counting hook sees it
  EXPECT_EQ(first.deallocations, 0);
  EXPECT_EQ(second.deallocations, 0);
  delete made_by_first;  // goes back to `first`, although `second` is installed now
  EXPECT_EQ(first.deallocations, 1);
  EXPECT_EQ(second.deallocations, 0);

  {
    UnifiedVector<double> made_by_second(50, 1.5);
    EXPECT_EQ(second.allocations, 1);
    InstallUnifiedMemoryHooks(nullptr);  // back to the default while the block is alive
  }
  EXPECT_EQ(second.deallocations, 1);
  EXPECT_EQ(first.allocations, 1);
}

// Growing a vector across a hook change moves the elements into a block of the new hooks and
// frees the old block with its own hooks.
TEST_F(UnifiedAllocatorTest, GrowingAcrossAHookChangeKeepsTheContents) {
  static CountingHooks hooks("grow");
  hooks.allocations = hooks.deallocations = 0;
  UnifiedVector<int> v(10);
  std::iota(v.begin(), v.end(), 0);
  InstallUnifiedMemoryHooks(&hooks.hooks);
  v.resize(10000, -1);
  EXPECT_EQ(hooks.allocations, 1);
  EXPECT_EQ(hooks.deallocations, 0);  // the old block went to the default deallocator
  EXPECT_EQ(&UnifiedBlockHooks(v.data()), &hooks.hooks);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(v[i], i);
  EXPECT_EQ(v[9999], -1);
  UnifiedVector<int>().swap(v);
  EXPECT_EQ(hooks.deallocations, 1);
}

TEST_F(UnifiedAllocatorTest, FailingHooksThrowBadAlloc) {
  static UnifiedMemoryHooks failing{[](size_t, void*) -> void* { return nullptr; },
                                    [](void*, size_t, void*) {}, nullptr, "failing"};
  InstallUnifiedMemoryHooks(&failing);
  EXPECT_THROW(UnifiedVector<float>(16), std::bad_alloc);
}

}  // namespace
}  // namespace plx

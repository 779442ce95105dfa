// How a kernel's argument struct (core/kernels/kernel_args.h) lists the sizes and arrays it
// takes, so that what every backend checks before a call is written once, not per kernel: the
// size and null checks of Backend (core/kernels/backend.cc), and the CUDA backend's residency
// checks and prefetches (cuda/cuda_backend.cu).
//
// An argument struct has `template <typename Visit> void ForEachArgument(Visit&& visit) const`,
// which calls `visit` with one KernelCount per size argument and one KernelBuffer per array.
// Host code only: the lists are walked before a launch, never inside a kernel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>

#include "core/grid/grid_view.h"

namespace plx {

// "grid.brick_slot" for the member `name` of the view `group`, or `name` alone without a group:
// how messages name an argument.
std::string ArgumentLabel(const char* group, const char* name);

// A size argument (an element count, a batch size): a negative one fails the call.
struct KernelCount {
  const char* group = nullptr;  // the view the size belongs to, or nullptr
  const char* name = "";
  int64_t value = 0;

  KernelCount Of(const char* view) const {
    KernelCount c = *this;
    c.group = view;
    return c;
  }
};

inline KernelCount Count(const char* name, int64_t value) { return {nullptr, name, value}; }

// What a kernel does with an array's elements.
enum class BufferAccess { kRead, kWrite, kReadWrite };

// The count of an array whose length its view does not carry (a grid's occupancy bits, the
// triangles' edge keys): it is neither size-checked nor prefetched.
struct UnknownSize {};
inline constexpr UnknownSize kUnknownSize{};

// One array a kernel reads or writes.
struct KernelBuffer {
  const char* group = nullptr;  // the view the array belongs to, or nullptr
  const char* name = "";
  const void* data = nullptr;
  int64_t count = 0;  // elements the kernel may touch (when `sized`)
  bool sized = true;
  size_t element_bytes = 0;
  BufferAccess access = BufferAccess::kRead;
  // Null fails the call. By default when the array has elements (or an unknown size); a
  // kernel that gives null a meaning (RenderPixels' pixel list) says Optional().
  bool required = true;
  // The caller's memory, read or written by the backend's host code (ReduceTrackingTerms'
  // sums): any memory will do, so the CUDA backend does not ask where it lives.
  bool host = false;
  // Large and used call after call (the grid's index, gradients, optimiser state): the CUDA
  // backend moves it to its device in bulk (docs/GPU.md) rather than page fault by page fault.
  bool prefetch = false;

  size_t bytes() const {
    return sized && count > 0 ? static_cast<size_t>(count) * element_bytes : 0;
  }

  KernelBuffer Of(const char* view) const {
    KernelBuffer b = *this;
    b.group = view;
    return b;
  }
  KernelBuffer Optional() const { return RequiredIf(false); }
  KernelBuffer RequiredIf(bool condition) const {
    KernelBuffer b = *this;
    b.required = condition;
    return b;
  }
  KernelBuffer OnHost() const {
    KernelBuffer b = *this;
    b.host = true;
    return b;
  }
  KernelBuffer Prefetched() const {
    KernelBuffer b = *this;
    b.prefetch = true;
    return b;
  }
};

template <typename T>
KernelBuffer MakeKernelBuffer(BufferAccess access, const char* name, const T* data, int64_t count) {
  KernelBuffer b;
  b.name = name;
  b.data = data;
  b.count = count;
  b.element_bytes = sizeof(T);
  b.access = access;
  b.required = count != 0;
  return b;
}

template <typename T>
KernelBuffer MakeKernelBuffer(BufferAccess access, const char* name, const T* data, UnknownSize) {
  KernelBuffer b = MakeKernelBuffer(access, name, data, 0);
  b.sized = false;
  b.required = true;
  return b;
}

// Read(name, data, count): an array the kernel only reads; Write: only writes; ReadWrite: both.
// `count` is in elements of T, or kUnknownSize.
template <typename T, typename Size>
KernelBuffer Read(const char* name, const T* data, Size count) {
  return MakeKernelBuffer(BufferAccess::kRead, name, data, count);
}
template <typename T, typename Size>
KernelBuffer Write(const char* name, T* data, Size count) {
  return MakeKernelBuffer<T>(BufferAccess::kWrite, name, data, count);
}
template <typename T, typename Size>
KernelBuffer ReadWrite(const char* name, T* data, Size count) {
  return MakeKernelBuffer<T>(BufferAccess::kReadWrite, name, data, count);
}

// The arrays of the views several kernels share, each under the argument's name (`view`).
// A grid: its brick tables and index (the bricks themselves come from the same allocator as the
// tables, core/grid/brick_storage.h, so the tables stand for them).
template <typename Visit>
void VisitGrid(Visit&& visit, const char* view, const GridView& g) {
  const int64_t bricks = g.num_bricks;
  const int64_t index = int64_t{g.dims[0]} * g.dims[1] * g.dims[2];
  visit(Count("num_bricks", bricks).Of(view));
  visit(Read("brick_density", g.brick_density, bricks).Of(view));
  visit(Read("brick_sh", g.brick_sh, bricks).Of(view));
  visit(Read("brick_origin", g.brick_origin, 3 * bricks).Of(view));
  visit(Read("brick_slot", g.brick_slot, index).Of(view).Prefetched());
  visit(Read("block_cells", g.block_cells, index).Of(view));
  // Read only in active blocks: null is fine for a grid without any.
  visit(Read("cell_bits", g.cell_bits, kUnknownSize).Of(view).Optional());
}

// The parameters a kernel writes through a GridWriteView of `grid` (its occupancy bits, which
// only some kernels write, are listed by those kernels).
template <typename Visit>
void VisitGridWrite(Visit&& visit, const char* view, const GridView& grid, const GridWriteView& w,
                    BufferAccess access) {
  KernelBuffer density = Write("brick_density", w.brick_density, grid.num_bricks).Of(view);
  KernelBuffer sh = Write("brick_sh", w.brick_sh, grid.num_bricks).Of(view);
  density.access = sh.access = access;
  visit(density);
  visit(sh);
}

// Gradient buffers in `grid`'s slot layout, accumulated into (read and written).
template <typename Visit>
void VisitGrad(Visit&& visit, const char* view, const GridView& grid, const GridGradView& g) {
  const int64_t vertices = grid.num_vertices();
  visit(ReadWrite("density", g.density, vertices).Of(view).Prefetched());
  visit(ReadWrite("sh", g.sh, vertices * kShCoeffCount).Of(view).Prefetched());
  visit(ReadWrite("touched", g.touched, vertices).Of(view));
  visit(ReadWrite("brick_touched", g.brick_touched, grid.num_bricks).Of(view));
}

// Calls f(const KernelCount&) for each size argument of `args`.
template <typename Args, typename F>
void ForEachCount(const Args& args, F&& f) {
  args.ForEachArgument([&](const auto& item) {
    if constexpr (std::is_same_v<std::decay_t<decltype(item)>, KernelCount>) f(item);
  });
}

// Calls f(const KernelBuffer&) for each array of `args`.
template <typename Args, typename F>
void ForEachBuffer(const Args& args, F&& f) {
  args.ForEachArgument([&](const auto& item) {
    if constexpr (std::is_same_v<std::decay_t<decltype(item)>, KernelBuffer>) f(item);
  });
}

}  // namespace plx

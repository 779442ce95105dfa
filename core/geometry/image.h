// Minimal owning image types for the engine (OpenCV stays at the I/O boundary, core/io).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/common/unified_allocator.h"

namespace plx {

// Row-major, interleaved channels. Pixels live in a UnifiedVector so kernels of every backend
// can read them (core/common/unified_allocator.h).
template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  int channels = 1;
  UnifiedVector<T> data;

  Image() = default;
  Image(int w, int h, int c, T fill = T{}) : width(w), height(h), channels(c),
        data(static_cast<size_t>(w) * h * c, fill) {}

  bool empty() const { return data.empty(); }
  int64_t num_pixels() const { return static_cast<int64_t>(width) * height; }
  T* pixel(int u, int v) { return data.data() + (static_cast<int64_t>(v) * width + u) * channels; }
  const T* pixel(int u, int v) const {
    return data.data() + (static_cast<int64_t>(v) * width + u) * channels;
  }
};

using ColorImage = Image<float>;  // 3 channels, linear RGB in [0, 1]
using DepthImage = Image<float>;  // 1 channel, z-depth in metres, 0 = invalid

}  // namespace plx

// Minimal owning image types for the engine (OpenCV stays at the I/O boundary, core/io).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
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

// Colour and depth share Image<float>'s layout and API but are distinct types, so passing a
// depth image where a colour one is expected (or the reverse) does not compile. Code generic
// over images takes an Image<T> and accepts both; turning a plain Image<float> into one of
// them must be spelled out.
struct ColorImage : Image<float> {  // 3 channels, linear RGB in [0, 1]
  using Image<float>::Image;
  ColorImage() = default;
  explicit ColorImage(Image<float> image) : Image<float>(std::move(image)) {}
};

struct DepthImage : Image<float> {  // 1 channel, z-depth in metres, 0 = invalid
  using Image<float>::Image;
  DepthImage() = default;
  explicit DepthImage(Image<float> image) : Image<float>(std::move(image)) {}
};

}  // namespace plx

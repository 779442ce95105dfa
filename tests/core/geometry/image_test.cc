#include "core/geometry/image.h"

#include <type_traits>

#include <gtest/gtest.h>

namespace plx {
namespace {

// Colour and depth are separate types: handing one to code that wants the other must not
// compile (both used to be Image<float>, so a swapped argument built and ran).
static_assert(!std::is_convertible_v<DepthImage, ColorImage>);
static_assert(!std::is_convertible_v<ColorImage, DepthImage>);
static_assert(!std::is_convertible_v<const DepthImage&, const ColorImage&>);
static_assert(!std::is_convertible_v<const ColorImage&, const DepthImage&>);
// A plain Image<float> becomes either one only when spelled out.
static_assert(!std::is_convertible_v<Image<float>, ColorImage>);
static_assert(!std::is_convertible_v<Image<float>, DepthImage>);
static_assert(std::is_constructible_v<ColorImage, Image<float>>);
// Code generic over images still takes both, and the layout is Image<float>'s.
static_assert(std::is_convertible_v<const ColorImage&, const Image<float>&>);
static_assert(std::is_convertible_v<const DepthImage&, const Image<float>&>);
static_assert(sizeof(ColorImage) == sizeof(Image<float>));
static_assert(sizeof(DepthImage) == sizeof(Image<float>));

template <typename T>
T Sum(const Image<T>& image) {
  T sum{};
  for (const T& v : image.data) sum += v;
  return sum;
}

TEST(ImageTest, ColourAndDepthKeepTheImageApi) {
  ColorImage color(4, 3, 3, 0.5f);
  DepthImage depth(4, 3, 1, 2.0f);
  EXPECT_EQ(color.num_pixels(), 12);
  EXPECT_EQ(depth.num_pixels(), 12);
  color.pixel(1, 2)[2] = 1.0f;
  depth.pixel(3, 0)[0] = 0.0f;
  EXPECT_EQ(color.data[(2 * 4 + 1) * 3 + 2], 1.0f);
  EXPECT_EQ(depth.data[3], 0.0f);
  EXPECT_FLOAT_EQ(Sum(color), 35 * 0.5f + 1.0f);  // templates deduce T through the base
  EXPECT_FLOAT_EQ(Sum(depth), 11 * 2.0f);
  EXPECT_TRUE(ColorImage().empty());
  EXPECT_EQ(DepthImage(Image<float>(2, 2, 1, 7.0f)).data[3], 7.0f);
}

}  // namespace
}  // namespace plx

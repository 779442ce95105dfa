// Stateless per-index random numbers for drawing rays and pixels: the same seed gives the same
// draw on every backend and thread count, so CPU and CUDA runs can be compared ray for ray.
#pragma once

#include "core/common/host_device.h"

namespace plx {

// Stateless per-index random numbers (PCG hash), identical on both backends for the same seed.
PLX_HD unsigned int PcgHash(unsigned int x) {
  const unsigned int state = x * 747796405u + 2891336453u;
  const unsigned int word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
  return (word >> 22u) ^ word;
}

// Uniform integer in [0, n) for item `i` of draw `seed`.
PLX_HD unsigned long long HashIndex(unsigned int seed, long long i, unsigned long long n) {
  const unsigned int a = PcgHash(static_cast<unsigned int>(i) ^ PcgHash(seed));
  const unsigned int b = PcgHash(a ^ static_cast<unsigned int>(i >> 32) ^ 0x9e3779b9u);
  const unsigned long long r = (static_cast<unsigned long long>(a) << 32) | b;
  return r % n;
}

}  // namespace plx

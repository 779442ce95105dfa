// Wall time since a steady-clock instant, in milliseconds: what the trackers and the SLAM
// session report per frame and what a time budget is held to.
#pragma once

#include <chrono>

namespace plx {

inline double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace plx

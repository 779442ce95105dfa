// Luma of a linear-RGB pixel (Rec. 601 weights): the one intensity the front-end's parts
// agree on (the odometry's pyramid, relocalisation's ORB image and thumbnail).
#pragma once

namespace plx {

inline float Luma(const float* rgb) { return 0.299f * rgb[0] + 0.587f * rgb[1] + 0.114f * rgb[2]; }

}  // namespace plx

// Trivially copyable inputs and parameters of the kernel drivers (core/kernels/*_impl.h).
#pragma once

#include <cstdint>

#include "core/grid/render_options.h"
#include "core/math/camera_ray.h"
#include "core/math/depth_noise.h"

namespace plx {

// One mapping keyframe on the backend: camera, colour [h*w*3] in [0,1], z-depth [h*w] (m).
struct TrainingFrameView {
  CameraView camera;
  const float* color = nullptr;
  const float* depth = nullptr;
};

// All training rays: pixel `ray_pixel[i]` (v * width + u) of frame `ray_frame[i]`, every one
// with valid depth. Batches draw from these uniformly with replacement.
struct TrainingRaysView {
  const TrainingFrameView* frames = nullptr;
  const uint32_t* ray_frame = nullptr;
  const uint32_t* ray_pixel = nullptr;
  int64_t num_rays = 0;
  // Rays [recent_begin, num_rays) belong to the most recent keyframes (rays are stored in
  // keyframe order): a local window that MappingBatchParams::recent_batch draws from.
  int64_t recent_begin = 0;
};

struct MappingBatchParams {
  uint32_t seed = 0;           // draws this batch's rays (same seed, same rays on every backend)
  int64_t batch_size = 0;
  // The first recent_batch rays of the batch are drawn from the recent keyframes only
  // (TrainingRaysView::recent_begin), the rest from every keyframe: SLAM's local window keeps
  // new geometry converging as the keyframe count grows. 0 = uniform over all rays.
  int64_t recent_batch = 0;
  // L = mean( |C^ - C|^2 / 3 + depth_weight * color_sigma^2 * rho((D^ - D) / sigma(z)) ):
  // depth residuals count in units of the sensor's noise at that depth, relative to a colour
  // noise of color_sigma, so near, precise depth constrains geometry and far, noisy depth does
  // not drown the colour. rho is the square, or Huber with threshold depth_huber (in sigmas).
  float depth_weight = 1.0f;
  float color_sigma = 0.1f;
  DepthNoiseModel depth_noise;
  float depth_sigma_floor = 0.001f;  // metres
  float depth_huber = 3.0f;          // noise sigmas; 0 = pure square
  float sh_min_weight = 0.0f;  // see MappingRayBackward
  RenderOptions render;
};

// Per-ray loss terms written by the mapping step, for progress and convergence checks.
struct MappingRayLoss {
  float color_sq;  // sum over channels of (C^ - C)^2
  float depth_abs; // |D^ - D| in metres
  float opacity;
};

struct RmsPropParams {
  float lr_density = 1.0f;
  float lr_sh = 1e-2f;
  float beta = 0.95f;
  float epsilon = 1e-8f;
  float sigma_threshold = 1e-8f;  // densities crossing it upwards mark their cells occupied
  // Work items per brick (a power of two dividing 512): 1 on the CPU, where one thread per brick
  // skips untouched bricks whole; a GPU wants many threads per brick (its backend sets this).
  int brick_slices = 1;
};

// RMSProp running averages, same slot layout as the grid.
struct OptimizerStateView {
  float* rms_density = nullptr;  // [num_vertices]
  float* rms_sh = nullptr;       // [num_vertices * 27]
};

}  // namespace plx

// Driver: one mapping batch (forward + backward per ray). Compiled by core/cpu/mapping_cpu.cc
// and cuda/mapping_cuda.cu.
#pragma once

#include <cmath>

#include "core/kernels/kernel_types.h"
#include "core/kernels/ray_mapping_backward.h"
#include "core/kernels/ray_render.h"
#include "core/math/hash.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const MappingForwardBackwardArgs& args) {
  const GridView g = args.grid;
  const GridGradView gg = args.grad;
  const TrainingRaysView set = args.rays;
  const MappingBatchParams p = args.params;
  MappingRayLoss* const losses = args.losses;
  const float inv_batch = 1.0f / static_cast<float>(p.batch_size);
  ParallelFor(ctx, p.batch_size, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t recent = set.num_rays - set.recent_begin;
    const int64_t ray =
        i < p.recent_batch && recent > 0
            ? set.recent_begin + static_cast<int64_t>(HashIndex(p.seed, i, recent))
            : static_cast<int64_t>(HashIndex(p.seed, i, set.num_rays));
    const TrainingFrameView& frame = set.frames[set.ray_frame[ray]];
    const uint32_t pixel = set.ray_pixel[ray];
    const int u = static_cast<int>(pixel % frame.camera.width);
    const int v = static_cast<int>(pixel / frame.camera.width);
    Vec3f origin, dir;
    float range_per_z;
    PixelRay(frame.camera, u, v, &origin, &dir, &range_per_z);
    const float target_range = frame.depth[pixel] * range_per_z;
    const float* target_color = frame.color + 3 * pixel;

    const RayRenderResult<float> fwd = RenderRay(g, origin, dir, p.render);
    float dL_dcolor[3];
    float color_sq = 0.0f;
    for (int c = 0; c < 3; ++c) {
      const float e = fwd.color[c] - target_color[c];
      color_sq += e * e;
      dL_dcolor[c] = 2.0f * e * inv_batch / 3.0f;
    }
    const float e_depth = fwd.depth - target_range;
    const float abs_depth = fabsf(e_depth);
    float sigma = p.depth_noise.Sigma(frame.depth[pixel]);
    sigma = sigma > p.depth_sigma_floor ? sigma : p.depth_sigma_floor;
    float scaled = e_depth / sigma;  // d rho / d scaled is 2 scaled, clipped by the Huber bound
    if (p.depth_huber > 0.0f && fabsf(scaled) > p.depth_huber) {
      scaled = scaled > 0.0f ? p.depth_huber : -p.depth_huber;
    }
    const float dL_ddepth =
        2.0f * p.depth_weight * p.color_sigma * p.color_sigma * scaled / sigma * inv_batch;
    MappingRayBackward(g, gg, origin, dir, p.render, fwd, dL_dcolor, dL_ddepth, p.sh_min_weight);
    losses[i] = MappingRayLoss{color_sq, abs_depth, fwd.opacity};
  });
}

}  // namespace plx::PLX_BACKEND_NS

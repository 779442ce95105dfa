// Driver: render a set of pixels. Compiled by core/cpu/render_cpu.cc and cuda/render_cuda.cu.
#pragma once

#include "core/kernels/kernel_types.h"
#include "core/kernels/ray_render.h"

namespace plx::PLX_BACKEND_NS {

void Run(const ExecContext& ctx, const RenderPixelsArgs& args) {
  const GridView g = args.grid;
  const CameraView cam = args.camera;
  const RenderOptions opt = args.options;
  const int32_t* const pixels = args.pixels;
  float* const color = args.color;
  float* const depth = args.depth;
  float* const opacity = args.opacity;
  float* const median_depth = args.median_depth;
  ParallelFor(ctx, args.count, [=] PLX_HD_LAMBDA(int64_t i) {
    const int64_t pixel = pixels != nullptr ? pixels[i] : i;
    const int u = static_cast<int>(pixel % cam.width);
    const int v = static_cast<int>(pixel / cam.width);
    Vec3f origin, dir;
    float range_per_z;
    PixelRay(cam, u, v, &origin, &dir, &range_per_z);
    const RayRenderResult<float> r = RenderRay(g, origin, dir, opt);
    color[3 * i + 0] = r.color[0];
    color[3 * i + 1] = r.color[1];
    color[3 * i + 2] = r.color[2];
    depth[i] = r.depth;
    opacity[i] = r.opacity;
    median_depth[i] = r.median_depth;
  });
}

}  // namespace plx::PLX_BACKEND_NS

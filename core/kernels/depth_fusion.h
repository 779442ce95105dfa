// Depth-guided initialisation of a vertex (our addition to the paper's method): a projective
// truncated signed distance, averaged over the keyframes that see the vertex, becomes a density
// step at the observed surface, and the colours seen near the surface become the SH DC term.
// Mapping then starts from a map that already renders roughly right, instead of from a uniform
// fog (reference: sigma = 0.1 everywhere), and spends its budget on refinement.
#pragma once

#include "core/common/host_device.h"
#include "core/kernels/kernel_types.h"
#include "core/math/depth_noise.h"
#include "core/math/rigid_transform.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/vec3.h"

namespace plx {

struct FusionParams {
  // Signed distances are clamped to +truncation(z) and observations further behind the surface
  // than that are ignored, with truncation(z) = max(min_truncation, sigmas * noise.Sigma(z)).
  float min_truncation = 0.08f;  // metres
  float truncation_sigmas = 3.0f;
  DepthNoiseModel noise;
  // Weight of an observation that sees past the vertex (free space) relative to one that sees a
  // surface at it. Below 1, a surface a few keyframes measured survives views that disagree.
  float free_space_weight = 1.0f;
  float ramp = 0.02f;         // metres over which density rises from 0 to sigma_max
  float sigma_max = 200.0f;   // density (1/m) given to vertices behind the surface
  float color_band = 0.03f;   // metres (+ noise sigma); colour comes from observations this close
  float min_depth = 0.05f;
  float max_depth = 10.0f;
};

// The projective truncated signed distance of a point, averaged over the frames that see it:
// what both fusion (a density step) and the observed surface of a mesh (its zero crossing,
// core/mesh/observed_surface.h) are made of.
struct ProjectiveTsdf {
  float tsdf;    // metres, positive in front of the surface; valid when weight > 0
  float weight;  // summed observation weights; 0: no frame measured depth in front of or at it
  float color[3];
  float color_count;  // observations within the colour band; colour valid when > 0
};

// Without colour (kWithColor false) the frames' colour images are not read and may be null.
template <bool kWithColor = true>
PLX_HD ProjectiveTsdf AverageProjectiveTsdf(const Vec3f& p, const TrainingFrameView* frames,
                                            int num_frames, const FusionParams& params) {
  float sdf_sum = 0.0f, sdf_count = 0.0f, tsdf_scale_sum = 0.0f;
  ProjectiveTsdf out{0.0f, 0.0f, {0.0f, 0.0f, 0.0f}, 0.0f};
  for (int f = 0; f < num_frames; ++f) {
    const CameraView& cam = frames[f].camera;
    const RigidTransformf& T = cam.world_T_camera;
    // camera_T_world applied to p: R^T (p - t).
    const Vec3f d = p - T.translation();
    const Vec3f pc{T.r[0] * d.x + T.r[3] * d.y + T.r[6] * d.z,
                   T.r[1] * d.x + T.r[4] * d.y + T.r[7] * d.z,
                   T.r[2] * d.x + T.r[5] * d.y + T.r[8] * d.z};
    if (pc.z < params.min_depth) continue;
    const float u = cam.fx * pc.x / pc.z + cam.cx;
    const float v = cam.fy * pc.y / pc.z + cam.cy;
    if (!(u >= 0.0f && v >= 0.0f && u < cam.width && v < cam.height)) continue;
    const int pixel = static_cast<int>(v) * cam.width + static_cast<int>(u);
    const float measured = frames[f].depth[pixel];
    if (measured <= 0.0f || measured > params.max_depth) continue;
    const float sdf = measured - pc.z;
    const float sigma = params.noise.Sigma(measured);
    float truncation = params.truncation_sigmas * sigma;
    truncation = truncation > params.min_truncation ? truncation : params.min_truncation;
    if (sdf < -truncation) continue;  // hidden behind the observed surface
    // Truncated distances in units of the truncation, so near and far observations weigh alike.
    const float weight = sdf < truncation ? 1.0f : params.free_space_weight;
    sdf_sum += weight * (sdf < truncation ? sdf : truncation) / truncation;
    sdf_count += weight;
    tsdf_scale_sum += weight * truncation;
    if (kWithColor && fabsf(sdf) < params.color_band + sigma) {
      const float* c = frames[f].color + 3 * pixel;
      out.color[0] += c[0];
      out.color[1] += c[1];
      out.color[2] += c[2];
      out.color_count += 1.0f;
    }
  }
  out.weight = sdf_count;
  if (sdf_count > 0.0f) out.tsdf = sdf_sum / sdf_count * (tsdf_scale_sum / sdf_count);
  if (out.color_count > 0.0f) {
    for (int c = 0; c < 3; ++c) out.color[c] /= out.color_count;
  }
  return out;
}

struct VertexFusion {
  float density;
  float color[3];
  bool observed;        // some keyframe measured depth in front of or at the vertex
  bool color_observed;  // some keyframe saw the vertex near its surface
};

PLX_HD VertexFusion FuseVertex(const Vec3f& p, const TrainingFrameView* frames, int num_frames,
                               const FusionParams& params) {
  const ProjectiveTsdf t = AverageProjectiveTsdf(p, frames, num_frames, params);
  VertexFusion out{0.0f, {0.5f, 0.5f, 0.5f}, t.weight > 0.0f, t.color_count > 0.0f};
  if (out.observed) {
    float occupancy = 0.5f - t.tsdf / params.ramp;
    occupancy = occupancy < 0.0f ? 0.0f : (occupancy > 1.0f ? 1.0f : occupancy);
    out.density = params.sigma_max * occupancy;
  }
  if (out.color_observed) {
    for (int c = 0; c < 3; ++c) out.color[c] = t.color[c];
  }
  return out;
}

}  // namespace plx

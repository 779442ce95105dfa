// The surface the keyframes saw, once: a mesh of the map that has no back faces and no surfaces
// in space no keyframe observed.
//
// The density iso-surface (ExtractMesh) has a second crossing behind every wall, where depth
// fusion ends the solid and nothing ever constrains it, and floaters wherever a little density
// was left in free space. Here each keyframe's view is rendered from the map (its surface depth,
// where the transmittance falls to 1/2: the first crossing along each ray the keyframe saw),
// and those depths are fused into a projective truncated signed distance at the grid's
// vertices (the same averaging as depth fusion, core/kernels/depth_fusion.h). The mesh is that
// field's zero crossing: vertices in front of a rendered surface are free space, vertices
// within the truncation behind it are inside, and vertices further behind or seen by no
// keyframe have no value, so no cell touching them has a surface. A wall's back, the inside of
// a box, a floater that rays pass through (it renders nothing) and space no keyframe looked at
// give no triangles; a surface is where the views agree it is, weighted by how many saw it.
//
// Rendered rather than measured depth: the map file keeps the keyframes' poses, not their
// images, and the rendered depth is the optimised map's (held-out depth L1 about a third of a
// TSDF's of the same frames, docs/BENCHMARKS.md), so the mesh follows what the map learned.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/formats/map_keyframe.h"
#include "core/geometry/triangle_mesh.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mesh/iso_surface.h"

namespace plx {

struct ObservedSurfaceOptions {
  // Keyframe views are rendered at this fraction of their resolution (pixels rounded). At 0.5
  // a 640x480 keyframe's pixel spans 4 mm at 1 m, well below a voxel; rendering is most of the
  // work, so this sets the cost.
  double render_scale = 1.0;
  // Bounds the work of a map with many keyframes (a long SLAM session): when rendering every
  // keyframe at render_scale would pass this many pixels in all, they are all rendered at the
  // smaller scale that keeps to it, so every view still carves its free space. About 40
  // keyframes of 640x480 at full size: rendering them takes about 20 s on 2 CPU cores
  // (infinitam_teddy's SLAM map: 26 keyframes, 14 s), inside the viewer's 60 s for a mesh.
  int64_t max_rendered_pixels = 12'000'000;
  // Truncation of the signed distance, in voxels, at every range. Vertices further behind
  // every view's surface than this have no value. Thin is better, down to where grazing views
  // start leaving holes: on teddy 3 voxels gave F-score 0.520, 2 gave 0.537, 1.5 0.546 but
  // Replica's recall fell (0.991 -> 0.981); docs/BENCHMARKS.md.
  float truncation_voxels = 2.0f;
};

// InvalidArgument naming the field (render_scale in (0, 1], max_rendered_pixels > 0,
// truncation_voxels >= 1).
absl::Status ValidateObservedSurfaceOptions(const ObservedSurfaceOptions& options);

// The observed surface's mesh of `map` as seen from `keyframes` (their poses and intrinsics).
// options.iso_level is not used; region, filters, colours and the triangle limit apply as in
// ExtractMesh. For a region only the keyframes that may see it are rendered (and the field is
// made for its bricks only), so the work follows the box; boxes tile the whole map's surface
// exactly as long as the pixel budget does not shrink the views of one and not the other.
// FailedPrecondition when `keyframes` is empty (the caller then falls back to the density
// surface, or says the map has no keyframes); otherwise errors as ExtractMesh's, and CANCELLED
// when `cancelled` returns true (asked between keyframes and between mesh slices).
absl::StatusOr<TriangleMesh> ExtractObservedMesh(
    const PlenoxelMap& map, const MapKeyframes& keyframes, Backend& backend,
    const MeshOptions& options, const ObservedSurfaceOptions& surface = {},
    const std::function<bool()>& cancelled = nullptr);

// The observed field at the vertices of the bricks `slots` (values [grid vertices], written
// there only): frames[i] is keyframes[i]'s view (its rendered depth). Bricks go in groups of
// 4x4x4 and each group's launch of Backend::ObserveSurface reads only the keyframes that may
// see the group's box with depth up to `max_depth`. A keyframe that cannot see a vertex adds
// nothing to its average, so the field is bit for bit the one a single launch over every
// keyframe gives, at the cost of the keyframes each place has instead of all of them (a long
// SLAM run has hundreds). Vertices of a group no keyframe may see are left as they are.
absl::Status ObserveFieldByGroups(const SparseGrid& grid, absl::Span<const int32_t> slots,
                                  const std::vector<const MapKeyframe*>& keyframes,
                                  absl::Span<const TrainingFrameView> frames,
                                  const FusionParams& params, float max_depth, Backend& backend,
                                  float* values);

}  // namespace plx

// Levels of detail: a triangle mesh simplified to at most a triangle budget the client names
// (a headset draws 100 k triangles smoothly, not the 2 M a room has at 2 cm), with
// meshoptimizer's quadric edge collapse (Debian's libmeshoptimizer, 0.18).
//
// Why on positions only: meshoptimizer 0.18 has no attribute-aware simplification
// (meshopt_simplifyWithAttributes came in 0.20), and it does not need one here. An edge collapse
// moves one end onto the other, so every vertex of the result is a vertex of the input with
// its own normal (the density gradient there) and colour: nothing is interpolated, and the
// attributes are compacted with the positions. The marching-cubes mesh has one vertex per
// position (shared cell edges are merged), so there are no attribute seams to keep either.
#pragma once

#include <cstdint>
#include <functional>

#include "absl/status/statusor.h"
#include "core/geometry/triangle_mesh.h"

namespace plx {

struct SimplifiedMesh {
  TriangleMesh mesh;
  int64_t input_triangles = 0;
  // How far (metres) the surface moved, as the quadric error measures it, summed over the
  // passes (each measures from its own input); 0 when nothing was simplified.
  double error_m = 0.0;
  // False when the topology-preserving collapse could not reach the budget (pinched or
  // non-manifold vertices it may not move) and clustering finished the job: the result may
  // then close small holes or join pieces closer than the error.
  bool topology_kept = true;
};

// At most `target_triangles` (> 0) triangles of `mesh`. A mesh already within the budget comes
// back unchanged (error 0). Otherwise:
//   1. meshopt_simplify with no error bound, in passes that each halve the triangles until the
//      budget (one deep pass folds flat regions over in 0.18). The budget is the client's hard
//      limit (what it can hold and draw), so an error bound could only make it miss; the error
//      reached is reported instead (a client that finds it too coarse asks for more).
//      Collapses go cheapest first, so where a budget leaves room the error stays small: on a
//      room the flat walls and floor lose their triangles long before edges and objects do.
//   2. If pinned vertices stop it above the budget, meshopt_simplifySloppy (vertex clustering)
//      on that result reaches it.
// The result's triangles are reordered for the GPU's vertex cache and its vertices compacted
// in first-use order, so a LOD is also laid out for drawing. Degenerate triangles are dropped.
// InvalidArgument for a budget <= 0 or a mesh whose arrays disagree or name missing vertices;
// CANCELLED when `cancelled` (asked between the steps) says so; out of memory is
// RESOURCE_EXHAUSTED.
absl::StatusOr<SimplifiedMesh> SimplifyMesh(const TriangleMesh& mesh, int64_t target_triangles,
                                            const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

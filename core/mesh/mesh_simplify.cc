#include "core/mesh/mesh_simplify.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <cfloat>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"

static_assert(MESHOPTIMIZER_VERSION >= 180,
              "meshoptimizer 0.18 or newer (meshopt_simplify with options and result_error)");

namespace plx {
namespace {

constexpr size_t kPositionStride = 3 * sizeof(float);

// meshoptimizer measures error relative to the mesh's extent (its largest side); FLT_MAX is
// "no bound": collapses stop at the budget only.
constexpr float kNoErrorBound = FLT_MAX;

// Keeps the vertices `indices` use, in first-use order, renumbering `indices` to match.
TriangleMesh Compact(const TriangleMesh& mesh, std::vector<uint32_t>& indices) {
  std::vector<int32_t> remap(static_cast<size_t>(mesh.num_vertices()), -1);
  TriangleMesh out;
  int32_t next = 0;
  for (uint32_t& v : indices) {
    if (remap[v] < 0) remap[v] = next++;
    v = static_cast<uint32_t>(remap[v]);
  }
  out.positions.resize(3 * static_cast<size_t>(next));
  out.normals.resize(3 * static_cast<size_t>(next));
  out.colors.resize(3 * static_cast<size_t>(next));
  for (size_t v = 0; v < remap.size(); ++v) {
    if (remap[v] < 0) continue;
    const size_t to = 3 * static_cast<size_t>(remap[v]);
    for (int c = 0; c < 3; ++c) {
      out.positions[to + c] = mesh.positions[3 * v + c];
      out.normals[to + c] = mesh.normals[3 * v + c];
      out.colors[to + c] = mesh.colors[3 * v + c];
    }
  }
  out.triangles.assign(indices.begin(), indices.end());
  return out;
}

// Drops triangles that name a vertex twice (a collapse can leave none; clustering can).
void DropDegenerate(std::vector<uint32_t>& indices) {
  size_t kept = 0;
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    const uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
    if (a == b || b == c || a == c) continue;
    indices[kept++] = a;
    indices[kept++] = b;
    indices[kept++] = c;
  }
  indices.resize(kept);
}

}  // namespace

absl::StatusOr<SimplifiedMesh> SimplifyMesh(const TriangleMesh& mesh, int64_t target_triangles,
                                            const std::function<bool()>& cancelled) {
  if (target_triangles <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("target_triangles: must be > 0, got ", target_triangles));
  }
  if (absl::Status s = CheckTriangleMesh(mesh); !s.ok()) return s;
  return CatchAllocationFailure("simplifying the mesh", [&]() -> absl::StatusOr<SimplifiedMesh> {
    SimplifiedMesh out;
    out.input_triangles = mesh.num_triangles();
    if (mesh.num_triangles() <= target_triangles) {
      out.mesh = mesh;
      return out;
    }
    const size_t vertex_count = static_cast<size_t>(mesh.num_vertices());
    const size_t target_indices = 3 * static_cast<size_t>(target_triangles);
    const float* positions = mesh.positions.data();
    // Relative errors times this are metres.
    const float scale = meshopt_simplifyScale(positions, vertex_count, kPositionStride);

    std::vector<uint32_t> indices(mesh.triangles.begin(), mesh.triangles.end());
    std::vector<uint32_t> source;
    float relative_error = 0.0f;
    // Halving passes rather than one pass to the budget: meshoptimizer 0.18 checks each
    // collapse for flipped triangles against the mesh as the pass began, and in one deep pass
    // neighbouring collapses fold flat regions over (11 of 72 triangles of a flat square at 1%
    // faced down; none in halving passes). Each pass's error is measured from its own input,
    // so their sum is what is reported for the distance from the full mesh.
    while (indices.size() > target_indices) {
      const size_t pass_target = std::max(target_indices, indices.size() / 6 * 3);
      source.swap(indices);
      indices.resize(source.size());  // the worst case is the input's size
      float pass_error = 0.0f;
      indices.resize(meshopt_simplify(indices.data(), source.data(), source.size(), positions,
                                      vertex_count, kPositionStride, pass_target, kNoErrorBound,
                                      /*options=*/0, &pass_error));
      relative_error += pass_error;
      if (cancelled && cancelled()) return absl::CancelledError("mesh simplification cancelled");
      if (indices.size() > pass_target) break;  // pinned vertices: collapses are done
    }
    if (indices.size() > target_indices) {
      // Pinned vertices stopped the collapses short of the budget: cluster what is left.
      source.swap(indices);
      indices.assign(source.size(), 0);
      float sloppy_error = 0.0f;
      indices.resize(meshopt_simplifySloppy(indices.data(), source.data(), source.size(),
                                            positions, vertex_count, kPositionStride,
                                            target_indices, kNoErrorBound, &sloppy_error));
      // Each pass moved the surface by at most its own error: the sum bounds both.
      relative_error += sloppy_error;
      out.topology_kept = false;
      if (cancelled && cancelled()) return absl::CancelledError("mesh simplification cancelled");
    }
    DropDegenerate(indices);
    if (indices.size() > target_indices) {
      return absl::InternalError(absl::StrCat("simplification left ", indices.size() / 3,
                                              " triangles over the budget of ",
                                              target_triangles));
    }
    meshopt_optimizeVertexCache(indices.data(), indices.data(), indices.size(), vertex_count);
    out.mesh = Compact(mesh, indices);
    out.error_m = static_cast<double>(relative_error) * scale;
    return out;
  });
}

}  // namespace plx

#include "core/geometry/triangle_mesh.h"

#include "absl/strings/str_cat.h"

namespace plx {

absl::Status CheckTriangleMesh(const TriangleMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (n % 3 != 0 || mesh.normals.size() != n || mesh.colors.size() != n ||
      mesh.triangles.size() % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh arrays disagree: ", n, " position, ", mesh.normals.size(), " normal, ",
        mesh.colors.size(), " colour values and ", mesh.triangles.size(), " face indices"));
  }
  for (int32_t v : mesh.triangles) {
    if (v < 0 || v >= mesh.num_vertices()) {
      return absl::InvalidArgumentError(absl::StrCat("a face names vertex ", v, " of ",
                                                     mesh.num_vertices()));
    }
  }
  return absl::OkStatus();
}

}  // namespace plx

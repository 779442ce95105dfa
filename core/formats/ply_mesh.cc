#include "core/formats/ply_mesh.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/allocation_guard.h"
#include "core/formats/ply_binary.h"

namespace plx {
namespace {

// Bytes per vertex (6 floats, 3 uchar) and per face (count byte, 3 int32).
constexpr size_t kVertexBytes = 6 * 4 + 3;
constexpr size_t kFaceBytes = 1 + 3 * 4;

}  // namespace

std::string PlyRegionComment(const AxisBox& box) {
  return absl::StrFormat("%s%.17g %.17g %.17g %.17g %.17g %.17g\n", kPlyRegionComment,
                         box.min[0], box.min[1], box.min[2], box.max[0], box.max[1],
                         box.max[2]);
}

absl::StatusOr<PlyMesh> EncodePlyMesh(const TriangleMesh& mesh, absl::string_view source,
                                      const std::optional<AxisBox>& region) {
  if (absl::Status s = CheckTriangleMesh(mesh); !s.ok()) return s;
  return CatchAllocationFailure("writing the mesh", [&]() -> absl::StatusOr<PlyMesh> {
    PlyMesh out;
    out.vertices = mesh.num_vertices();
    out.faces = mesh.num_triangles();
    out.bytes = absl::StrCat(
        "ply\nformat binary_little_endian 1.0\n", ply::SourceComment(source),
        region ? PlyRegionComment(*region) : std::string(), "element vertex ", out.vertices,
        "\nproperty float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face ",
        out.faces, "\nproperty list uchar int vertex_indices\nend_header\n");
    out.bytes.reserve(out.bytes.size() + out.vertices * kVertexBytes + out.faces * kFaceBytes);
    for (int64_t v = 0; v < out.vertices; ++v) {
      for (int c = 0; c < 3; ++c) ply::Append(&out.bytes, mesh.positions[3 * v + c]);
      for (int c = 0; c < 3; ++c) ply::Append(&out.bytes, mesh.normals[3 * v + c]);
      for (int c = 0; c < 3; ++c) ply::Append(&out.bytes, mesh.colors[3 * v + c]);
    }
    for (int64_t f = 0; f < out.faces; ++f) {
      ply::Append(&out.bytes, uint8_t{3});
      for (int c = 0; c < 3; ++c) ply::Append(&out.bytes, mesh.triangles[3 * f + c]);
    }
    return out;
  });
}

}  // namespace plx

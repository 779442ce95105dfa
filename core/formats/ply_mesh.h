// A triangle mesh as binary little-endian PLY: element `vertex` with float x y z nx ny nz and
// uchar red green blue, element `face` with `list uchar int vertex_indices` (three per face).
// The layout MeshLab, Open3D, Blender and Unity's importers read.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/geometry/axis_box.h"
#include "core/geometry/triangle_mesh.h"

namespace plx {

struct PlyMesh {
  std::string bytes;
  int64_t vertices = 0;
  int64_t faces = 0;
};

// How the header names the region of a mesh cut to a box (MeshOptions::region): this, then
// "xmin ymin zmin xmax ymax zmax" (map coordinates, metres) and a newline.
inline constexpr char kPlyRegionComment[] = "comment plenoxd region: ";

// That comment line of `box`, every coordinate written exactly (17 significant digits).
std::string PlyRegionComment(const AxisBox& box);

// `source` goes into the header's comment (the map's source text), and `region`, when set, into
// a second one (kPlyRegionComment). InvalidArgument when the mesh's arrays disagree in size or
// a face names a vertex that does not exist; out of memory is RESOURCE_EXHAUSTED.
absl::StatusOr<PlyMesh> EncodePlyMesh(const TriangleMesh& mesh, absl::string_view source,
                                      const std::optional<AxisBox>& region = std::nullopt);

}  // namespace plx

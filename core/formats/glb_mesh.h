// A triangle mesh as binary glTF 2.0 (.glb), the format headsets, three.js, Blender, Unity and
// Unreal load: one scene, one node, one mesh with one indexed triangle primitive. Written with
// Debian's tinygltf.
//
// Layout (one buffer, the GLB's BIN chunk, each view 4-byte aligned):
//   POSITION  float VEC3 with min/max (required by glTF), metres, in the map's frame
//   NORMAL    float VEC3, unit length, pointing into free space
//   COLOR_0   unsigned byte VEC4, normalized, alpha 255: the vertex colours (RGBA rather than
//             RGB so every vertex stays 4-byte aligned without a stride)
//   indices   unsigned short when there are at most 65 535 vertices, else unsigned int
//             (glTF forbids the type's largest value as an index), counter-clockwise seen from
//             the side the normals face (glTF's front face)
// The material is unlit (KHR_materials_unlit, used but not required: a loader without it falls
// back to the matte, non-metallic PBR material given): the colours are what the cameras saw,
// lighting included, so shading them again would darken them twice. It is double-sided because
// the surfaces no camera saw (the backs of walls) are left out of the mesh.
//
// Frame: glTF is right-handed with +Y up; plenoxd maps are right-handed with +Z up where they
// have an up at all (the synthetic room; TUM's and Replica's ground-truth worlds are within
// about 30 degrees of it). The vertices stay in map coordinates and the node carries the turn
// (a -90 degree rotation about X, map (x, y, z) -> glTF (x, z, -y)), so three.js shows a map
// upright, Blender's importer (which turns glTF's +Y up back into its +Z up) shows it in map
// coordinates, and a client that anchors the mesh to map poses (Track, Slam) reads the
// primitive's positions as they are or drops the node's rotation. A map whose world is a
// camera's frame (a SLAM map started without a pose prior: y down) needs the client's turn. The
// frame is that of the map version meshed: after a SLAM loop closure, the corrected one.
//
// The asset's extras say what the file is: {"plenoxd": {"source": the map's source text,
// "triangles": in the file, "full_triangles": before simplification, "lod_error_m": the
// simplification's error in metres, "up": "+Z"}}, and for the mesh of a region of the map
// (MeshOptions::region) "region": {"min": [x, y, z], "max": [x, y, z]} in map coordinates.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/geometry/axis_box.h"
#include "core/geometry/triangle_mesh.h"

namespace plx {

// The glTF media type (RFC: model/gltf-binary) for HTTP answers.
inline constexpr char kGlbMediaType[] = "model/gltf-binary";

// What the file records about where the mesh came from (the asset's extras).
struct GlbMeshMetadata {
  std::string source;          // the map's source text; invalid UTF-8 bytes become '?'
  int64_t full_triangles = 0;  // before simplification (0: the mesh was not simplified)
  double lod_error_m = 0.0;    // the simplification's error, metres
  std::optional<AxisBox> region;  // the box the mesh was cut to; unset: the whole map
};

struct GlbMesh {
  std::string bytes;
  int64_t vertices = 0;
  int64_t faces = 0;
};

// The GLB of `mesh`. Normals are renormalised (glTF wants unit length); the rare zero or
// non-finite one becomes +Z. An empty mesh gives a valid file with the node and no mesh.
// InvalidArgument when the mesh's arrays disagree (CheckTriangleMesh), a position is not
// finite, or the file would pass glTF's 4 GiB limit; out of memory is RESOURCE_EXHAUSTED.
// Memory: the file is built in a tinygltf model and written once, so while it is written about
// three copies of the vertex and index data (28 bytes a vertex, 6 or 12 a triangle) are held.
absl::StatusOr<GlbMesh> EncodeGlbMesh(const TriangleMesh& mesh, const GlbMeshMetadata& metadata);

// What a GLB's header and JSON chunk say: enough for a client to report what it received
// without holding the whole file (the JSON chunk comes first).
struct GlbMeshInfo {
  int64_t file_bytes = 0;  // the header's total length
  int64_t vertices = 0;    // POSITION counts over every triangle primitive
  int64_t triangles = 0;   // their index counts / 3 (or vertex counts / 3 without indices)
  // From the asset's plenoxd extras when present (else 0).
  int64_t full_triangles = 0;
  double lod_error_m = 0.0;
  std::optional<AxisBox> region;  // the extras' region when it has one (six finite numbers)
};

// How many leading bytes of a GLB ReadGlbMeshInfo needs (the header and the JSON chunk), from
// its first 20 bytes; InvalidArgument when they are not a glTF 2 binary header.
absl::StatusOr<int64_t> GlbInfoBytes(absl::string_view first_bytes);

// Reads `prefix` (at least GlbInfoBytes of the file). InvalidArgument naming the problem when it
// is not a GLB, the JSON chunk is cut or not JSON, or an accessor it needs is missing.
absl::StatusOr<GlbMeshInfo> ReadGlbMeshInfo(absl::string_view prefix);

}  // namespace plx

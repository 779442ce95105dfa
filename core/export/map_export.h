// A map as one file in the forms `plenox export` and the daemon's Export offer: the coloured
// points on the surface of the density field as PLY (core/formats/ply_export.h), or a triangle
// mesh by marching cubes (core/mesh/iso_surface.h) as PLY (core/formats/ply_mesh.h) or binary
// glTF (core/formats/glb_mesh.h), optionally simplified to a triangle budget, a level of
// detail (core/mesh/mesh_simplify.h). Both callers build it here, so the same spec gives the
// same file in-process and on the daemon.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/formats/map_keyframe.h"
#include "core/formats/ply_export.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mesh/iso_surface.h"

namespace plx {

// Which surface a mesh is of.
enum class MeshSurface {
  // The observed surface when the map has keyframes, else the density iso-surface.
  kAuto,
  // What the keyframes saw, once (core/mesh/observed_surface.h); needs the map's keyframes.
  kObserved,
  // The density's iso-surface at MeshOptions::iso_level (core/mesh/iso_surface.h): back faces
  // behind walls where the unobserved filter misses them, and every floater.
  kDensity,
};

// "auto", "observed", "density": the names flags, URLs and messages use.
const char* MeshSurfaceName(MeshSurface surface);
// InvalidArgument "expected auto, observed or density, got \"...\"".
absl::StatusOr<MeshSurface> MeshSurfaceFromName(absl::string_view name);

// The mesh of `map` on the surface `surface` names (kAuto resolved by `keyframes`): the one
// choice that the export and the viewer share. FailedPrecondition for kObserved without
// keyframes; otherwise ExtractObservedMesh's or ExtractMesh's errors.
absl::StatusOr<TriangleMesh> ExtractMapMesh(const PlenoxelMap& map, const MapKeyframes& keyframes,
                                            MeshSurface surface, Backend& backend,
                                            const MeshOptions& options,
                                            const std::function<bool()>& cancelled = nullptr);

// How a mesh is written.
enum class MeshFileFormat {
  kPly,  // binary little-endian PLY (MeshLab, Open3D, Blender)
  kGlb,  // binary glTF 2.0 (headsets, three.js, Blender, game engines)
};

// The most triangles a level of detail may ask for: beyond the mesh limit it could only be the
// full mesh.
inline constexpr int64_t kMaxLodTriangles = kDefaultMaxMeshTriangles;

// Which file to make. The defaults are core's: a point cloud above kDefaultExportMinDensity, or
// a mesh with MeshOptions' defaults (kDefaultMeshIsoLevel, kDefaultMaxMeshTriangles) as PLY.
struct ExportSpec {
  bool mesh = false;                             // false: points
  float min_density = kDefaultExportMinDensity;  // points only
  // Mesh only; its `region` cuts the mesh to a box of the map (the file then records the box:
  // the GLB's extras, a PLY header comment).
  MeshOptions mesh_options;
  MeshSurface mesh_surface = MeshSurface::kAuto;  // mesh only
  MeshFileFormat mesh_format = MeshFileFormat::kPly;  // mesh only
  // Mesh only: simplify to at most this many triangles (SimplifyMesh); 0 = the full mesh.
  int64_t lod_triangles = 0;
};

// InvalidArgument naming the field: lod_triangles negative or over kMaxLodTriangles, a glTF
// format, a level of detail or a region (mesh_options.region) asked of points, or mesh options
// ValidateMeshOptions refuses (a region that is not a finite box with min < max among them).
absl::Status ValidateExportSpec(const ExportSpec& spec);

struct MapExport {
  std::string bytes;
  int64_t vertices = 0;  // the points, or the mesh's vertices
  int64_t faces = 0;     // the mesh's triangles; 0 for points
  // A mesh's triangles before simplification (== faces without a level of detail), and the
  // simplification's error in metres (SimplifiedMesh::error_m).
  int64_t full_faces = 0;
  double lod_error_m = 0.0;
};

// The file of `map` as `spec` asks. The mesh runs on `backend` (the points need none; the
// simplification runs on the calling thread). `cancelled` is asked as the work goes on; true
// stops it with CANCELLED. RESOURCE_EXHAUSTED out of memory or over the mesh's triangle limit
// (checked on the full mesh, before simplification); INVALID_ARGUMENT for a spec that
// ValidateExportSpec refuses.
// `keyframes` are the map's (the map file's, or the daemon's for the version): the observed
// surface is made from them; empty, a mesh is the density surface unless the spec names the
// observed one (FailedPrecondition).
absl::StatusOr<MapExport> ExportMap(const ExportSpec& spec, const PlenoxelMap& map,
                                    const MapKeyframes& keyframes, Backend& backend,
                                    const std::function<bool()>& cancelled = nullptr);

}  // namespace plx

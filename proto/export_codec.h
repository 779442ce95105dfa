// plenoxd.v1 ExportRequest <-> core/export's ExportSpec: which file of a map a client asks for
// (PLY points, or a mesh as PLY or binary glTF, its options and level of detail). The daemon
// reads it, the CLI writes it.
#pragma once

#include "absl/status/statusor.h"
#include "core/export/map_export.h"
#include "proto/wire.h"

namespace plx {

// The request's format and options over core's defaults: a 0 min_density, iso_level or
// max_triangles means kDefaultExportMinDensity, kDefaultMeshIsoLevel or kDefaultMaxMeshTriangles.
// INVALID_ARGUMENT naming the field: an unknown format or mesh_color (proto3 enums are open, an
// unknown number must not become the default), a min_density or iso_level that is negative or
// not finite, a field of the other format set (a mesh field, lod_triangles included, on
// POINTS; min_density on a mesh), max_triangles or min_component_triangles over
// kDefaultMaxMeshTriangles, lod_triangles over kMaxLodTriangles, or mesh options that
// ValidateMeshOptions refuses (a region that is not finite or has min >= max on an axis:
// "region: ..."). A region becomes MeshOptions::region. The map name is not read here (the
// caller checks it).
absl::StatusOr<ExportSpec> ExportSpecFromProto(const pb::ExportRequest& request);

// The inverse: the format and that format's fields, sent as they are (a spec holds resolved
// values, so the daemon's defaults are not asked for). The map is the caller's to set.
pb::ExportRequest ExportSpecToProto(const ExportSpec& spec);

}  // namespace plx

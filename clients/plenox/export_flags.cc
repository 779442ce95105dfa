#include "clients/plenox/export_flags.h"

#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/formats/ply_export.h"

namespace plx::cli {
namespace {

// The format --out's extension names ("ply", "glb"), or "" for any other name.
std::string FormatOfName(const std::string& out) {
  const std::string lower = absl::AsciiStrToLower(out);
  if (absl::EndsWith(lower, ".glb")) return "glb";
  if (absl::EndsWith(lower, ".ply")) return "ply";
  return "";
}

// The mesh's format: --format when given (ply or glb), else the one --out names, else ply.
absl::StatusOr<MeshFileFormat> MeshFormatFromFlags(const FlagSet& flags, bool mesh) {
  const std::string out = flags.GetString("out");
  const std::string named = FormatOfName(out);
  std::string format = named.empty() ? "ply" : named;
  if (flags.IsSet("format")) {
    format = flags.GetString("format");
    if (format != "ply" && format != "glb") {
      return absl::InvalidArgumentError(
          absl::StrCat("--format: expected ply or glb, got \"", format, "\""));
    }
    if (!named.empty() && named != format) {
      return absl::InvalidArgumentError(absl::StrCat("--format ", format, " but --out \"", out,
                                                     "\" names a .", named, " file"));
    }
  }
  if (!mesh && format == "glb") {
    return absl::InvalidArgumentError(
        flags.IsSet("format")
            ? "--format glb applies to --mesh only (glTF holds the mesh, not points)"
            : absl::StrCat("--out \"", out, "\" is a glTF file, which holds a mesh: add --mesh"));
  }
  return format == "glb" ? MeshFileFormat::kGlb : MeshFileFormat::kPly;
}

// --bbox "xmin,ymin,zmin,xmax,ymax,zmax": six numbers, a finite box with min < max.
absl::StatusOr<AxisBox> BoxFromFlag(const std::string& text) {
  const std::vector<std::string> parts = absl::StrSplit(text, ',');
  AxisBox box;
  bool ok = parts.size() == 6;
  for (size_t i = 0; ok && i < parts.size(); ++i) {
    double& v = i < 3 ? box.min[i] : box.max[i - 3];
    ok = absl::SimpleAtod(absl::StripAsciiWhitespace(parts[i]), &v);
  }
  if (!ok) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--bbox: expected six numbers xmin,ymin,zmin,xmax,ymax,zmax (metres, map "
        "coordinates), got \"", text.substr(0, 200), "\""));
  }
  if (absl::Status s = CheckAxisBox(box, "--bbox"); !s.ok()) return s;
  return box;
}

}  // namespace

void AddExportFlags(FlagSet& flags) {
  flags.Add("out", "FILE", "file to write: FILE.ply, or FILE.glb for a mesh as glTF",
            std::nullopt, true)
      .AddSwitch("mesh", "write a triangle mesh (marching cubes) instead of points")
      .Add("format", "ply|glb",
           "mesh: binary PLY, or binary glTF 2.0 for headsets, three.js and Blender (default: "
           "glb when --out ends in .glb, else ply)")
      .Add("lod-triangles", "N",
           absl::StrCat("mesh: a level of detail, simplified to at most N triangles (0 = the "
                        "full mesh; at most ", kMaxLodTriangles, ")"),
           "0")
      .Add("bbox", "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
           "mesh: only this box of the map (metres, map coordinates): the triangles of the "
           "voxels whose centres are in it, kept whole")
      .Add("min-density", "D",
           absl::StrCat("points: where the density exceeds D (0 = the default, ",
                        kDefaultExportMinDensity, ")"),
           "0")
      .Add("iso-level", "D",
           absl::StrCat("mesh: the surface's density in 1/m (0 = the default, ",
                        kDefaultMeshIsoLevel, ")"),
           "0")
      .Add("min-component", "N", "mesh: drop connected pieces of fewer than N triangles", "0")
      .Add("max-triangles", "N",
           absl::StrCat("mesh: fail rather than build a full mesh of more triangles (0 = ",
                        kDefaultMaxMeshTriangles, ", also the most allowed)"),
           "0")
      .Add("mesh-surface", "auto|observed|density",
           "mesh: the surface the map's keyframes saw (rendered from their poses, fused; "
           "no back faces, nothing unseen), or the density's iso-surface; auto: observed when "
           "the map has keyframes",
           "auto")
      .AddSwitch("keep-unobserved",
                 "mesh: keep surfaces no view saw (e.g. the backs of walls)")
      .Add("mesh-color", "dc|normal",
           "mesh: view-independent colour, or as seen looking along the vertex normal", "dc");
}

absl::StatusOr<ExportSpec> ExportSpecFromFlags(const FlagSet& flags) {
  ExportSpec spec;
  spec.mesh = flags.GetSwitch("mesh");
  absl::StatusOr<double> min_density = flags.GetDouble("min-density", 0.0, 1e9);
  if (!min_density.ok()) return min_density.status();
  absl::StatusOr<double> iso = flags.GetDouble("iso-level", 0.0, 1e9);
  if (!iso.ok()) return iso.status();
  absl::StatusOr<int> components = flags.GetInt("min-component", 0, kDefaultMaxMeshTriangles);
  if (!components.ok()) return components.status();
  absl::StatusOr<int> max_triangles = flags.GetInt("max-triangles", 0, kDefaultMaxMeshTriangles);
  if (!max_triangles.ok()) return max_triangles.status();
  absl::StatusOr<int> lod_triangles = flags.GetInt("lod-triangles", 0, kMaxLodTriangles);
  if (!lod_triangles.ok()) return lod_triangles.status();
  const std::string color = flags.GetString("mesh-color");
  if (color != "dc" && color != "normal") {
    return absl::InvalidArgumentError(
        absl::StrCat("--mesh-color: expected dc or normal, got \"", color, "\""));
  }
  absl::StatusOr<MeshFileFormat> format = MeshFormatFromFlags(flags, spec.mesh);
  if (!format.ok()) return format.status();
  absl::StatusOr<MeshSurface> surface = MeshSurfaceFromName(flags.GetString("mesh-surface"));
  if (!surface.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--mesh-surface: ", surface.status().message()));
  }
  if (!spec.mesh) {
    const char* mesh_flag = *iso != 0                    ? "--iso-level"
                            : *components != 0           ? "--min-component"
                            : *max_triangles != 0        ? "--max-triangles"
                            : *lod_triangles != 0        ? "--lod-triangles"
                            : flags.IsSet("bbox")        ? "--bbox"
                            : flags.GetSwitch("keep-unobserved") ? "--keep-unobserved"
                            : color != "dc"              ? "--mesh-color"
                            : *surface != MeshSurface::kAuto ? "--mesh-surface"
                                                         : nullptr;
    if (mesh_flag != nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(mesh_flag, " applies to --mesh only"));
    }
    if (*min_density > 0) spec.min_density = static_cast<float>(*min_density);
    return spec;
  }
  if (*min_density != 0) {
    return absl::InvalidArgumentError("--min-density applies to points only (--mesh: --iso-level)");
  }
  MeshOptions& o = spec.mesh_options;
  if (*iso > 0) o.iso_level = static_cast<float>(*iso);
  o.min_component_triangles = *components;
  if (*max_triangles > 0) o.max_triangles = *max_triangles;
  o.keep_unobserved = flags.GetSwitch("keep-unobserved");
  o.color_mode = color == "normal" ? MeshColorMode::kViewAlongNormal : MeshColorMode::kDc;
  if (flags.IsSet("bbox")) {
    absl::StatusOr<AxisBox> box = BoxFromFlag(flags.GetString("bbox"));
    if (!box.ok()) return box.status();
    o.region = *box;
  }
  spec.mesh_format = *format;
  spec.mesh_surface = *surface;
  spec.lod_triangles = *lod_triangles;
  return spec;
}

}  // namespace plx::cli

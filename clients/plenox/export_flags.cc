#include "clients/plenox/export_flags.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "core/formats/ply_export.h"

namespace plx::cli {

void AddExportFlags(FlagSet& flags) {
  flags.Add("out", "FILE.ply", "PLY file to write", std::nullopt, true)
      .AddSwitch("mesh", "write a triangle mesh (marching cubes) instead of points")
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
           absl::StrCat("mesh: fail rather than build more triangles (0 = ",
                        kDefaultMaxMeshTriangles, ", also the most allowed)"),
           "0")
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
  const std::string color = flags.GetString("mesh-color");
  if (color != "dc" && color != "normal") {
    return absl::InvalidArgumentError(
        absl::StrCat("--mesh-color: expected dc or normal, got \"", color, "\""));
  }
  if (!spec.mesh) {
    const char* mesh_flag = *iso != 0                    ? "--iso-level"
                            : *components != 0           ? "--min-component"
                            : *max_triangles != 0        ? "--max-triangles"
                            : flags.GetSwitch("keep-unobserved") ? "--keep-unobserved"
                            : color != "dc"              ? "--mesh-color"
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
  return spec;
}

}  // namespace plx::cli

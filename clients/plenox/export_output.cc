#include "clients/plenox/export_output.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx::cli {

std::string ExportSummaryText(const ExportSummary& s) {
  if (!s.mesh) return absl::StrFormat("%d points", s.vertices);
  std::string text = absl::StrFormat("%d vertices, %d triangles", s.vertices, s.faces);
  if (s.full_faces > s.faces) {
    text += absl::StrFormat(" (a level of detail of %d, error %.1f mm)", s.full_faces,
                            1000.0 * s.lod_error_m);
  }
  if (s.region) text += absl::StrCat(" in the box ", AxisBoxText(*s.region));
  text += s.format == MeshFileFormat::kGlb ? ", glTF" : ", PLY";
  return text;
}

void AddExportSummaryJson(JsonObject& json, const ExportSummary& s) {
  if (!s.mesh) {
    json.Add("points", s.vertices);
  } else {
    json.Add("vertices", s.vertices).Add("faces", s.faces);
    json.Add("format", std::string(s.format == MeshFileFormat::kGlb ? "glb" : "ply"));
    json.Add("full_faces", s.full_faces).Add("lod_error_m", s.lod_error_m);
    if (s.region) {
      const AxisBox& b = *s.region;
      json.Add("bbox", absl::StrFormat("%.17g,%.17g,%.17g,%.17g,%.17g,%.17g", b.min[0],
                                       b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]));
    }
  }
  json.Add("bytes", static_cast<int64_t>(s.bytes));
}

}  // namespace plx::cli

// A small reader of the binary little-endian PLY meshes plenoxd writes
// (core/formats/ply_mesh.h), for tests: parses the header, then the `vertex` element's float
// and uchar properties by name and the `face` element's `list uchar int` indices. Anything
// else (ASCII, other types, other lists) is an error, so a writer that drifts from the format
// the tests expect fails them.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/geometry/triangle_mesh.h"

namespace plx::testing {

struct PlyMeshFile {
  TriangleMesh mesh;
  std::string comment;  // the first comment line's text
};

inline absl::StatusOr<PlyMeshFile> ReadPlyMesh(const std::string& bytes) {
  const std::string end = "end_header\n";
  const size_t header_end = bytes.find(end);
  if (bytes.rfind("ply\nformat binary_little_endian 1.0\n", 0) != 0 ||
      header_end == std::string::npos) {
    return absl::InvalidArgumentError("not a binary little-endian PLY");
  }
  struct Property {
    std::string name, type;
  };
  int64_t vertices = -1, faces = -1;
  std::vector<Property> vertex_properties;
  bool face_list = false;
  PlyMeshFile out;
  std::string element;
  for (absl::string_view line :
       absl::StrSplit(absl::string_view(bytes).substr(0, header_end), '\n')) {
    std::vector<std::string> w = absl::StrSplit(line, ' ', absl::SkipEmpty());
    if (w.empty() || w[0] == "ply" || w[0] == "format") continue;
    if (w[0] == "comment") {
      if (out.comment.empty()) out.comment = std::string(line.substr(8));
    } else if (w[0] == "element" && w.size() == 3) {
      element = w[1];
      int64_t n = 0;
      if (!absl::SimpleAtoi(w[2], &n)) return absl::InvalidArgumentError("bad element count");
      (element == "vertex" ? vertices : faces) = n;
    } else if (w[0] == "property" && element == "vertex" && w.size() == 3) {
      vertex_properties.push_back({w[2], w[1]});
    } else if (w[0] == "property" && element == "face" && w.size() == 5 && w[1] == "list" &&
               w[2] == "uchar" && w[3] == "int" && w[4] == "vertex_indices") {
      face_list = true;
    } else {
      return absl::InvalidArgumentError(absl::StrCat("unexpected header line: ", line));
    }
  }
  if (vertices < 0 || faces < 0 || !face_list) {
    return absl::InvalidArgumentError("header lacks the vertex or face element");
  }
  size_t at = header_end + end.size();
  auto take = [&](void* dst, size_t n) {
    if (at + n > bytes.size()) return false;
    std::memcpy(dst, bytes.data() + at, n);
    at += n;
    return true;
  };
  TriangleMesh& m = out.mesh;
  m.positions.assign(3 * vertices, 0.0f);
  m.normals.assign(3 * vertices, 0.0f);
  m.colors.assign(3 * vertices, 0);
  const std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz",
                                          "red", "green", "blue"};
  for (int64_t v = 0; v < vertices; ++v) {
    for (const Property& p : vertex_properties) {
      int slot = -1;
      for (size_t i = 0; i < names.size(); ++i) {
        if (names[i] == p.name) slot = static_cast<int>(i);
      }
      if (p.type == "float") {
        float value = 0.0f;
        if (!take(&value, 4)) return absl::InvalidArgumentError("file ends in the vertices");
        if (slot >= 0 && slot < 3) m.positions[3 * v + slot] = value;
        if (slot >= 3 && slot < 6) m.normals[3 * v + slot - 3] = value;
      } else if (p.type == "uchar") {
        uint8_t value = 0;
        if (!take(&value, 1)) return absl::InvalidArgumentError("file ends in the vertices");
        if (slot >= 6) m.colors[3 * v + slot - 6] = value;
      } else {
        return absl::InvalidArgumentError(absl::StrCat("unexpected type ", p.type));
      }
    }
  }
  for (int64_t f = 0; f < faces; ++f) {
    uint8_t count = 0;
    if (!take(&count, 1)) return absl::InvalidArgumentError("file ends in the faces");
    if (count != 3) return absl::InvalidArgumentError("a face is not a triangle");
    for (int c = 0; c < 3; ++c) {
      int32_t index = 0;
      if (!take(&index, 4)) return absl::InvalidArgumentError("file ends in the faces");
      m.triangles.push_back(index);
    }
  }
  if (at != bytes.size()) return absl::InvalidArgumentError("bytes after the last face");
  return out;
}

}  // namespace plx::testing

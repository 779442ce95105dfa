// What the binary PLY writers (ply_export.cc: points, ply_mesh.cc: meshes) share: values
// appended in little-endian order and the header's comment line.
#pragma once

#include <algorithm>
#include <cstring>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace plx::ply {

// Appends the bytes of a float, int32 or uint8 as stored: the project targets little-endian
// machines (x86-64, aarch64), which is the PLY format the headers announce.
template <typename T>
void Append(std::string* out, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  out->append(b, sizeof(T));
}

// "comment plenoxd map: <source>\n", with the source on one line ("unnamed" when empty).
inline std::string SourceComment(absl::string_view source) {
  std::string comment = source.empty() ? "unnamed" : std::string(source);
  std::replace_if(
      comment.begin(), comment.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
  return absl::StrCat("comment plenoxd map: ", comment, "\n");
}

}  // namespace plx::ply

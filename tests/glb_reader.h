// A strict reader of the binary glTF meshes plenoxd writes (core/formats/glb_mesh.h), for tests,
// written from the glTF 2.0 specification and independent of the writer: the 12-byte header
// (magic "glTF", version 2, total length == the file's size), a JSON chunk and a BIN chunk each
// a multiple of 4 bytes and nothing after them, then the one triangle primitive's accessors
// decoded through their buffer views with every offset and length checked against the BIN
// chunk. Anything the writer should not produce (other types, strides, sparse accessors, out of
// range indices, a count of 0) is an error, so a writer that drifts fails the tests.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "core/geometry/triangle_mesh.h"

namespace plx::testing {

struct GlbFile {
  nlohmann::json json;
  uint32_t json_chunk_bytes = 0;
  uint32_t bin_chunk_bytes = 0;  // 0: no BIN chunk
  int index_component_type = 0;  // 5123 (unsigned short) or 5125 (unsigned int); 0: no mesh
  TriangleMesh mesh;             // colours: COLOR_0's RGB (alpha checked to be 255)
  std::vector<double> position_min, position_max;  // the POSITION accessor's
};

namespace glb_detail {

inline uint32_t Le32(const std::string& b, size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);  // tests run on little-endian machines
  return v;
}

// The bytes of accessor `index`: checks its type and component type and that count elements
// fit its tightly packed view inside `bin`.
inline absl::StatusOr<std::string> AccessorBytes(const nlohmann::json& gltf,
                                                 const std::string& bin, int index,
                                                 const std::string& type, int component_type,
                                                 size_t element_bytes, size_t* count) {
  const nlohmann::json& a = gltf.at("accessors").at(index);
  if (a.value("type", "") != type || a.value("componentType", 0) != component_type) {
    return absl::InvalidArgumentError(absl::StrCat("accessor ", index, ": ", a.dump()));
  }
  if (a.contains("sparse") || a.value("byteOffset", 0) != 0) {
    return absl::InvalidArgumentError(absl::StrCat("accessor ", index, ": sparse or offset"));
  }
  *count = a.at("count").get<size_t>();
  if (*count == 0) return absl::InvalidArgumentError("glTF forbids an accessor count of 0");
  const nlohmann::json& view = gltf.at("bufferViews").at(a.at("bufferView").get<int>());
  const size_t offset = view.value("byteOffset", size_t{0});
  const size_t length = view.at("byteLength").get<size_t>();
  if (view.value("buffer", -1) != 0 || view.contains("byteStride") || offset % 4 != 0 ||
      length != *count * element_bytes || offset + length > bin.size()) {
    return absl::InvalidArgumentError(absl::StrCat("accessor ", index, "'s view: ", view.dump(),
                                                   " (BIN chunk ", bin.size(), " bytes)"));
  }
  return bin.substr(offset, length);
}

inline absl::StatusOr<GlbFile> ReadGlbThrowing(const std::string& bytes) {
  if (bytes.size() < 20 || Le32(bytes, 0) != 0x46546C67 || Le32(bytes, 4) != 2) {
    return absl::InvalidArgumentError("not a glTF 2 binary file");
  }
  if (Le32(bytes, 8) != bytes.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("header length ", Le32(bytes, 8), " != file size ", bytes.size()));
  }
  GlbFile out;
  out.json_chunk_bytes = Le32(bytes, 12);
  if (Le32(bytes, 16) != 0x4E4F534A || out.json_chunk_bytes % 4 != 0 ||
      20 + size_t{out.json_chunk_bytes} > bytes.size()) {
    return absl::InvalidArgumentError("bad JSON chunk header");
  }
  out.json = nlohmann::json::parse(bytes.substr(20, out.json_chunk_bytes), nullptr, false);
  if (out.json.is_discarded()) return absl::InvalidArgumentError("the JSON chunk is not JSON");
  size_t at = 20 + out.json_chunk_bytes;
  std::string bin;
  if (at < bytes.size()) {
    if (at + 8 > bytes.size()) return absl::InvalidArgumentError("cut BIN chunk header");
    out.bin_chunk_bytes = Le32(bytes, at);
    if (Le32(bytes, at + 4) != 0x004E4942 || out.bin_chunk_bytes % 4 != 0 ||
        at + 8 + out.bin_chunk_bytes != bytes.size()) {
      return absl::InvalidArgumentError("bad BIN chunk (type, alignment or length)");
    }
    bin = bytes.substr(at + 8, out.bin_chunk_bytes);
    if (!out.json.contains("buffers") || out.json["buffers"].size() != 1 ||
        out.json["buffers"][0].contains("uri") ||
        out.json["buffers"][0].at("byteLength").get<size_t>() > bin.size() ||
        bin.size() - out.json["buffers"][0].at("byteLength").get<size_t>() > 3) {
      return absl::InvalidArgumentError("buffer 0 does not describe the BIN chunk");
    }
  }
  if (!out.json.contains("meshes")) return out;
  const nlohmann::json& primitives = out.json.at("meshes").at(0).at("primitives");
  if (out.json["meshes"].size() != 1 || primitives.size() != 1) {
    return absl::InvalidArgumentError("expected one mesh with one primitive");
  }
  const nlohmann::json& primitive = primitives[0];
  if (primitive.value("mode", 4) != 4) return absl::InvalidArgumentError("not triangles");
  const nlohmann::json& attributes = primitive.at("attributes");
  {
    size_t n = 0, normal_n = 0, color_n = 0, index_n = 0;
    absl::StatusOr<std::string> positions = glb_detail::AccessorBytes(
        out.json, bin, attributes.at("POSITION").get<int>(), "VEC3", 5126, 12, &n);
    if (!positions.ok()) return positions.status();
    absl::StatusOr<std::string> normals = glb_detail::AccessorBytes(
        out.json, bin, attributes.at("NORMAL").get<int>(), "VEC3", 5126, 12, &normal_n);
    if (!normals.ok()) return normals.status();
    absl::StatusOr<std::string> colors = glb_detail::AccessorBytes(
        out.json, bin, attributes.at("COLOR_0").get<int>(), "VEC4", 5121, 4, &color_n);
    if (!colors.ok()) return colors.status();
    if (normal_n != n || color_n != n) return absl::InvalidArgumentError("attribute counts");
    const nlohmann::json& color_accessor =
        out.json["accessors"][attributes["COLOR_0"].get<int>()];
    if (!color_accessor.value("normalized", false)) {
      return absl::InvalidArgumentError("COLOR_0 as unsigned bytes must be normalized");
    }
    const nlohmann::json& position_accessor =
        out.json["accessors"][attributes["POSITION"].get<int>()];
    out.position_min = position_accessor.at("min").get<std::vector<double>>();
    out.position_max = position_accessor.at("max").get<std::vector<double>>();
    const int indices = primitive.at("indices").get<int>();
    out.index_component_type = out.json["accessors"][indices].value("componentType", 0);
    const size_t index_bytes = out.index_component_type == 5123 ? 2 : 4;
    absl::StatusOr<std::string> index_data = glb_detail::AccessorBytes(
        out.json, bin, indices, "SCALAR", out.index_component_type, index_bytes, &index_n);
    if (!index_data.ok()) return index_data.status();
    if (index_n % 3 != 0) return absl::InvalidArgumentError("index count not a multiple of 3");

    TriangleMesh& mesh = out.mesh;
    mesh.positions.resize(3 * n);
    mesh.normals.resize(3 * n);
    mesh.colors.resize(3 * n);
    std::memcpy(mesh.positions.data(), positions->data(), 12 * n);
    std::memcpy(mesh.normals.data(), normals->data(), 12 * n);
    for (size_t v = 0; v < n; ++v) {
      std::memcpy(&mesh.colors[3 * v], colors->data() + 4 * v, 3);
      if (static_cast<uint8_t>((*colors)[4 * v + 3]) != 255) {
        return absl::InvalidArgumentError("COLOR_0's alpha is not 255");
      }
    }
    mesh.triangles.resize(index_n);
    const uint32_t largest = index_bytes == 2 ? 0xFFFF : 0xFFFFFFFF;  // reserved by glTF
    for (size_t i = 0; i < index_n; ++i) {
      uint32_t v = 0;
      std::memcpy(&v, index_data->data() + index_bytes * i, index_bytes);
      if (v >= n || v == largest) {
        return absl::InvalidArgumentError(absl::StrCat("index ", v, " of ", n, " vertices"));
      }
      mesh.triangles[i] = static_cast<int32_t>(v);
    }
  }
  return out;
}

}  // namespace glb_detail

inline absl::StatusOr<GlbFile> ReadGlb(const std::string& bytes) {
  try {
    return glb_detail::ReadGlbThrowing(bytes);
  } catch (const nlohmann::json::exception& e) {  // a missing or mistyped member
    return absl::InvalidArgumentError(absl::StrCat("glTF JSON: ", e.what()));
  }
}

}  // namespace plx::testing

// ReadGlbMeshInfo: the counts a GLB's JSON chunk declares (core/formats/glb_mesh.h).
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <cstring>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/formats/glb_mesh.h"

namespace plx {
namespace {

constexpr uint32_t kGlbMagic = 0x46546C67;      // "glTF"
constexpr uint32_t kJsonChunkType = 0x4E4F534A;  // "JSON"
constexpr size_t kHeaderBytes = 12;
constexpr size_t kChunkHeaderBytes = 8;

uint32_t LoadLe32(absl::string_view bytes, size_t at) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data() + at);
  return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}

// The count of accessor `index`, or -1 when there is no such accessor with a count.
int64_t AccessorCount(const nlohmann::json& gltf, const nlohmann::json& index) {
  if (!index.is_number_unsigned() || !gltf.contains("accessors")) return -1;
  const nlohmann::json& accessors = gltf["accessors"];
  const uint64_t i = index.get<uint64_t>();
  if (!accessors.is_array() || i >= accessors.size()) return -1;
  const nlohmann::json& accessor = accessors[i];
  if (!accessor.is_object() || !accessor.contains("count")) return -1;
  const nlohmann::json& count = accessor["count"];
  return count.is_number_unsigned() ? static_cast<int64_t>(count.get<uint64_t>()) : -1;
}

// The box of an extras "region" ({"min": [3 numbers], "max": [3 numbers]}), or none when it is
// not one.
std::optional<AxisBox> RegionOf(const nlohmann::json& region) {
  if (!region.is_object()) return std::nullopt;
  AxisBox box;
  const std::pair<const char*, std::array<double, 3>*> corners[] = {{"min", &box.min},
                                                                     {"max", &box.max}};
  for (const auto& [key, corner] : corners) {
    if (!region.contains(key)) return std::nullopt;
    const nlohmann::json& values = region[key];
    if (!values.is_array() || values.size() != 3) return std::nullopt;
    for (int a = 0; a < 3; ++a) {
      if (!values[a].is_number()) return std::nullopt;
      (*corner)[a] = values[a].get<double>();
    }
  }
  return box;
}

}  // namespace

absl::StatusOr<int64_t> GlbInfoBytes(absl::string_view first_bytes) {
  if (first_bytes.size() < kHeaderBytes + kChunkHeaderBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat("not a GLB: ", first_bytes.size(), " bytes, the header needs 20"));
  }
  if (LoadLe32(first_bytes, 0) != kGlbMagic || LoadLe32(first_bytes, 4) != 2) {
    return absl::InvalidArgumentError("not a glTF 2 binary file (magic \"glTF\", version 2)");
  }
  if (LoadLe32(first_bytes, 16) != kJsonChunkType) {
    return absl::InvalidArgumentError("GLB: the first chunk is not JSON");
  }
  return static_cast<int64_t>(kHeaderBytes + kChunkHeaderBytes) + LoadLe32(first_bytes, 12);
}

absl::StatusOr<GlbMeshInfo> ReadGlbMeshInfo(absl::string_view prefix) {
  absl::StatusOr<int64_t> needed = GlbInfoBytes(prefix);
  if (!needed.ok()) return needed.status();
  if (static_cast<int64_t>(prefix.size()) < *needed) {
    return absl::InvalidArgumentError(absl::StrCat("GLB: the JSON chunk needs ", *needed,
                                                   " bytes, ", prefix.size(), " given"));
  }
  GlbMeshInfo info;
  info.file_bytes = LoadLe32(prefix, 8);
  const absl::string_view json_text =
      prefix.substr(kHeaderBytes + kChunkHeaderBytes, *needed - kHeaderBytes - kChunkHeaderBytes);
  // No exceptions: a parse error is a discarded value.
  const nlohmann::json gltf = nlohmann::json::parse(json_text.begin(), json_text.end(), nullptr,
                                                    /*allow_exceptions=*/false);
  if (gltf.is_discarded() || !gltf.is_object()) {
    return absl::InvalidArgumentError("GLB: the JSON chunk is not a JSON object");
  }
  if (gltf.contains("meshes") && gltf["meshes"].is_array()) {
    for (const nlohmann::json& mesh : gltf["meshes"]) {
      if (!mesh.is_object() || !mesh.contains("primitives")) continue;
      for (const nlohmann::json& primitive : mesh["primitives"]) {
        if (!primitive.is_object() || !primitive.contains("attributes")) continue;
        // Mode 4 (triangles) is the default.
        if (primitive.contains("mode") && primitive["mode"] != 4) continue;
        const nlohmann::json& attributes = primitive["attributes"];
        const int64_t vertices = attributes.is_object() && attributes.contains("POSITION")
                                     ? AccessorCount(gltf, attributes["POSITION"])
                                     : -1;
        if (vertices < 0) {
          return absl::InvalidArgumentError("GLB: a triangle primitive has no POSITION count");
        }
        int64_t corners = vertices;
        if (primitive.contains("indices")) {
          corners = AccessorCount(gltf, primitive["indices"]);
          if (corners < 0) return absl::InvalidArgumentError("GLB: an indices accessor is bad");
        }
        info.vertices += vertices;
        info.triangles += corners / 3;
      }
    }
  }
  const nlohmann::json* extras = nullptr;
  if (gltf.contains("asset") && gltf["asset"].is_object() && gltf["asset"].contains("extras")) {
    const nlohmann::json& e = gltf["asset"]["extras"];
    if (e.is_object() && e.contains("plenoxd") && e["plenoxd"].is_object()) extras = &e["plenoxd"];
  }
  if (extras != nullptr) {
    if (extras->contains("full_triangles") && (*extras)["full_triangles"].is_number()) {
      info.full_triangles = static_cast<int64_t>((*extras)["full_triangles"].get<double>());
    }
    if (extras->contains("lod_error_m") && (*extras)["lod_error_m"].is_number()) {
      info.lod_error_m = (*extras)["lod_error_m"].get<double>();
    }
    if (extras->contains("region")) info.region = RegionOf((*extras)["region"]);
  }
  return info;
}

}  // namespace plx

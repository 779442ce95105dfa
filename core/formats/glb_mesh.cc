#include "core/formats/glb_mesh.h"

#include <tiny_gltf.h>

#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <ostream>
#include <streambuf>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"

#ifndef PLX_VERSION
#define PLX_VERSION "unknown"
#endif

namespace plx {
namespace {

// glTF's largest unsigned short index is reserved (primitive restart), so 16-bit indices reach
// 65 535 vertices.
constexpr int64_t kMaxShortIndexedVertices = 65535;
// The GLB header's lengths are 32-bit.
constexpr uint64_t kMaxGlbBytes = std::numeric_limits<uint32_t>::max();
// Room for the JSON chunk besides the buffer (it is about 2 kB plus the source text).
constexpr size_t kJsonReserve = 64 * 1024;

// The map's +Z up to glTF's +Y up: -90 degrees about X, as a unit quaternion (x, y, z, w).
constexpr double kHalfSqrt2 = 0.70710678118654752440;

// An output stream buffer that appends to a string reserved in advance, so the file is written
// once into its final place (an ostringstream would grow by copies, then copy out).
class StringSink : public std::streambuf {
 public:
  explicit StringSink(std::string* out) : out_(out) {}

 protected:
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    out_->append(s, static_cast<size_t>(n));
    return n;
  }
  int_type overflow(int_type c) override {
    if (!traits_type::eq_int_type(c, traits_type::eof())) out_->push_back(static_cast<char>(c));
    return traits_type::not_eof(c);
  }

 private:
  std::string* out_;
};

// nlohmann's JSON (inside tinygltf) refuses strings that are not UTF-8; the source text is a
// path or a dataset name, so anything else in it becomes '?'.
std::string ValidUtf8(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  size_t i = 0;
  while (i < s.size()) {
    const auto b = static_cast<unsigned char>(s[i]);
    size_t n = 0;  // the sequence's length by its lead byte; 0: not a lead byte
    if (b < 0x80) {
      n = 1;
    } else if ((b >> 5) == 0x6) {
      n = 2;
    } else if ((b >> 4) == 0xE) {
      n = 3;
    } else if ((b >> 3) == 0x1E) {
      n = 4;
    }
    bool ok = n > 0 && i + n <= s.size();
    for (size_t k = 1; ok && k < n; ++k) ok = (static_cast<unsigned char>(s[i + k]) >> 6) == 0x2;
    // Overlong forms, surrogates and code points past U+10FFFF are not UTF-8 either.
    if (ok && n > 1) {
      uint32_t cp = b & (0x7F >> n);
      for (size_t k = 1; k < n; ++k) {
        cp = (cp << 6) | (static_cast<unsigned char>(s[i + k]) & 0x3F);
      }
      static constexpr uint32_t kMin[5] = {0, 0, 0x80, 0x800, 0x10000};
      ok = cp >= kMin[n] && cp <= 0x10FFFF && !(cp >= 0xD800 && cp <= 0xDFFF);
    }
    if (ok) {
      out.append(s, i, n);
      i += n;
    } else {
      out.push_back('?');
      ++i;
    }
  }
  return out;
}

// Appends `bytes` to the buffer as a new view; returns its index.
int AddView(tinygltf::Model& model, const void* bytes, size_t size, int target) {
  std::vector<unsigned char>& data = model.buffers[0].data;
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = data.size();
  view.byteLength = size;
  view.target = target;
  const auto* p = static_cast<const unsigned char*>(bytes);
  data.insert(data.end(), p, p + size);
  // Every view starts 4-byte aligned (glTF's rule for vertex attributes, and float reads).
  data.resize((data.size() + 3) / 4 * 4, 0);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size() - 1);
}

int AddAccessor(tinygltf::Model& model, int view, int component_type, int type, size_t count,
                bool normalized = false) {
  tinygltf::Accessor accessor;
  accessor.bufferView = view;
  accessor.componentType = component_type;
  accessor.type = type;
  accessor.count = count;
  accessor.normalized = normalized;
  model.accessors.push_back(accessor);
  return static_cast<int>(model.accessors.size() - 1);
}

tinygltf::Value AssetExtras(const GlbMeshMetadata& metadata, int64_t triangles) {
  tinygltf::Value::Object plenoxd;
  plenoxd["source"] = tinygltf::Value(ValidUtf8(metadata.source));
  // Triangle counts stay below 2^31 (the mesh limit is 20 M); doubles carry them exactly.
  plenoxd["triangles"] = tinygltf::Value(static_cast<double>(triangles));
  plenoxd["full_triangles"] = tinygltf::Value(
      static_cast<double>(metadata.full_triangles > 0 ? metadata.full_triangles : triangles));
  plenoxd["lod_error_m"] = tinygltf::Value(metadata.lod_error_m);
  plenoxd["up"] = tinygltf::Value(std::string("+Z"));
  if (metadata.region) {
    tinygltf::Value::Array lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo.push_back(tinygltf::Value(metadata.region->min[a]));
      hi.push_back(tinygltf::Value(metadata.region->max[a]));
    }
    tinygltf::Value::Object region;
    region["min"] = tinygltf::Value(std::move(lo));
    region["max"] = tinygltf::Value(std::move(hi));
    plenoxd["region"] = tinygltf::Value(std::move(region));
  }
  tinygltf::Value::Object extras;
  extras["plenoxd"] = tinygltf::Value(std::move(plenoxd));
  return tinygltf::Value(std::move(extras));
}

// Unit normals; zero or non-finite ones (a vertex no gradient or face gave a direction) +Z.
std::vector<float> UnitNormals(const std::vector<float>& normals) {
  std::vector<float> out(normals.size());
  for (size_t v = 0; v + 2 < normals.size(); v += 3) {
    const float x = normals[v], y = normals[v + 1], z = normals[v + 2];
    const float norm = std::sqrt(x * x + y * y + z * z);
    if (std::isfinite(norm) && norm > 1e-20f) {
      out[v] = x / norm;
      out[v + 1] = y / norm;
      out[v + 2] = z / norm;
    } else {
      out[v] = 0.0f;
      out[v + 1] = 0.0f;
      out[v + 2] = 1.0f;
    }
  }
  return out;
}

// The mesh's buffer views, accessors, material and mesh in `model`.
void AddMesh(tinygltf::Model& model, const TriangleMesh& mesh) {
  const size_t n = static_cast<size_t>(mesh.num_vertices());
  model.buffers.emplace_back();
  model.buffers[0].data.reserve(28 * n + 4 * mesh.triangles.size() + 16);

  const int positions = AddAccessor(
      model, AddView(model, mesh.positions.data(), 12 * n, TINYGLTF_TARGET_ARRAY_BUFFER),
      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);
  tinygltf::Accessor& p = model.accessors[positions];
  p.minValues.assign(3, std::numeric_limits<double>::infinity());
  p.maxValues.assign(3, -std::numeric_limits<double>::infinity());
  for (size_t v = 0; v < n; ++v) {
    for (int c = 0; c < 3; ++c) {
      const double x = mesh.positions[3 * v + c];
      p.minValues[c] = std::min(p.minValues[c], x);
      p.maxValues[c] = std::max(p.maxValues[c], x);
    }
  }

  const std::vector<float> normals = UnitNormals(mesh.normals);
  const int normal = AddAccessor(
      model, AddView(model, normals.data(), 12 * n, TINYGLTF_TARGET_ARRAY_BUFFER),
      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);

  std::vector<uint8_t> rgba(4 * n);
  for (size_t v = 0; v < n; ++v) {
    std::memcpy(&rgba[4 * v], &mesh.colors[3 * v], 3);
    rgba[4 * v + 3] = 255;
  }
  const int color = AddAccessor(
      model, AddView(model, rgba.data(), rgba.size(), TINYGLTF_TARGET_ARRAY_BUFFER),
      TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4, n, /*normalized=*/true);

  const size_t index_count = mesh.triangles.size();
  int indices = 0;
  if (mesh.num_vertices() <= kMaxShortIndexedVertices) {
    const std::vector<uint16_t> shorts(mesh.triangles.begin(), mesh.triangles.end());
    indices = AddAccessor(model,
                          AddView(model, shorts.data(), 2 * index_count,
                                  TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                          TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR,
                          index_count);
  } else {
    // int32 indices >= 0 have the same bytes as uint32.
    indices = AddAccessor(model,
                          AddView(model, mesh.triangles.data(), 4 * index_count,
                                  TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                          TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR,
                          index_count);
  }

  tinygltf::Material material;
  material.name = "captured colour (unlit)";
  material.emissiveFactor = {0.0, 0.0, 0.0};  // tinygltf writes an empty array otherwise
  material.doubleSided = true;
  material.pbrMetallicRoughness.metallicFactor = 0.0;
  material.pbrMetallicRoughness.roughnessFactor = 1.0;
  material.extensions["KHR_materials_unlit"] = tinygltf::Value(tinygltf::Value::Object());
  model.materials.push_back(material);
  model.extensionsUsed.push_back("KHR_materials_unlit");

  tinygltf::Primitive primitive;
  primitive.attributes["POSITION"] = positions;
  primitive.attributes["NORMAL"] = normal;
  primitive.attributes["COLOR_0"] = color;
  primitive.indices = indices;
  primitive.material = 0;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  tinygltf::Mesh gltf_mesh;
  gltf_mesh.name = "surface";
  gltf_mesh.primitives.push_back(primitive);
  model.meshes.push_back(gltf_mesh);
}

absl::Status CheckPositions(const TriangleMesh& mesh) {
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    if (!std::isfinite(mesh.positions[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", i / 3, " has a position that is not finite"));
    }
  }
  // Positions, normals, colours, 32-bit indices and the JSON: beyond 4 GiB GLB cannot say it.
  const uint64_t bytes = 28 * static_cast<uint64_t>(mesh.num_vertices()) +
                         4 * static_cast<uint64_t>(mesh.triangles.size()) + kJsonReserve;
  if (bytes > kMaxGlbBytes) {
    return absl::InvalidArgumentError(absl::StrCat("the mesh (", mesh.num_vertices(),
                                                   " vertices, ", mesh.num_triangles(),
                                                   " triangles) is over glTF's 4 GiB limit"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<GlbMesh> EncodeGlbMesh(const TriangleMesh& mesh, const GlbMeshMetadata& metadata) {
  if (absl::Status s = CheckTriangleMesh(mesh); !s.ok()) return s;
  if (absl::Status s = CheckPositions(mesh); !s.ok()) return s;
  return CatchAllocationFailure("writing the glTF mesh", [&]() -> absl::StatusOr<GlbMesh> {
    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "plenoxd " PLX_VERSION;
    model.asset.extras = AssetExtras(metadata, mesh.num_triangles());
    tinygltf::Node node;
    node.name = "map (+Z up turned to glTF's +Y up)";
    node.rotation = {-kHalfSqrt2, 0.0, 0.0, kHalfSqrt2};
    // glTF accessors must have count >= 1: an empty mesh is a node without one.
    if (mesh.num_triangles() > 0) {
      AddMesh(model, mesh);
      node.mesh = 0;
    }
    model.nodes.push_back(node);
    tinygltf::Scene scene;
    scene.name = "plenoxd map";
    scene.nodes.push_back(0);
    model.scenes.push_back(scene);
    model.defaultScene = 0;

    GlbMesh out;
    out.vertices = mesh.num_triangles() > 0 ? mesh.num_vertices() : 0;
    out.faces = mesh.num_triangles();
    const size_t buffer_bytes = model.buffers.empty() ? 0 : model.buffers[0].data.size();
    out.bytes.reserve(buffer_bytes + kJsonReserve + metadata.source.size());
    StringSink sink(&out.bytes);
    std::ostream stream(&sink);
    tinygltf::TinyGLTF writer;
    bool written = false;
    try {
      written = writer.WriteGltfSceneToStream(&model, stream, /*prettyPrint=*/false,
                                              /*writeBinary=*/true);
    } catch (const std::bad_alloc&) {
      throw;  // CatchAllocationFailure's
    } catch (const std::exception& e) {
      // nlohmann's JSON throws on what it cannot write; nothing we build should reach this.
      return absl::InternalError(absl::StrCat("writing the glTF JSON: ", e.what()));
    }
    if (!written || !stream) return absl::InternalError("tinygltf could not write the GLB");
    return out;
  });
}

}  // namespace plx

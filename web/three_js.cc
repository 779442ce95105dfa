#include "web/three_js.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <system_error>

#include "absl/strings/str_cat.h"

namespace plx::web {
namespace {

constexpr std::uintmax_t kMaxFileBytes = 8 << 20;  // three.min.js r111 is 0.6 MB

absl::StatusOr<std::string> ReadSmallFile(const std::filesystem::path& path) {
  std::error_code ec;
  const bool regular = std::filesystem::is_regular_file(path, ec);
  if (!regular) {
    return absl::NotFoundError(absl::StrCat(
        "three.js not found: ", path.string(),
        " is missing (install Debian's libjs-three: apt-get install libjs-three; or give the "
        "folder that holds three.min.js, examples/js/controls/OrbitControls.js and "
        "examples/js/loaders/GLTFLoader.js)"));
  }
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec || size > kMaxFileBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": ", ec ? ec.message() : "over 8 MiB, not three.js"));
  }
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) {
    return absl::UnavailableError(absl::StrCat(path.string(), ": cannot be read"));
  }
  return bytes;
}

}  // namespace

absl::StatusOr<ThreeJsFiles> LoadThreeJs(const std::string& dir) {
  const std::filesystem::path root(dir);
  ThreeJsFiles files;
  absl::StatusOr<std::string> three = ReadSmallFile(root / "three.min.js");
  if (!three.ok()) return three.status();
  absl::StatusOr<std::string> controls =
      ReadSmallFile(root / "examples" / "js" / "controls" / "OrbitControls.js");
  if (!controls.ok()) return controls.status();
  absl::StatusOr<std::string> gltf =
      ReadSmallFile(root / "examples" / "js" / "loaders" / "GLTFLoader.js");
  if (!gltf.ok()) return gltf.status();
  files.three = std::move(*three);
  files.orbit_controls = std::move(*controls);
  files.gltf_loader = std::move(*gltf);
  return files;
}

}  // namespace plx::web

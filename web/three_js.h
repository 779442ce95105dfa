// Debian's three.js (package libjs-three, r111), which the viewer page runs on: the library, and
// the orbit controls and glTF loader of its examples, read once when the viewer starts and
// served from memory (so a request never touches the file system and no path from a URL reaches
// it). No CDN, no download: the page works offline.
#pragma once

#include <string>

#include "absl/status/statusor.h"

namespace plx::web {

// Where Debian installs libjs-three.
inline constexpr char kDefaultThreeJsDir[] = "/usr/share/javascript/three";

struct ThreeJsFiles {
  std::string three;           // three.min.js: the THREE global
  std::string orbit_controls;  // examples/js/controls/OrbitControls.js: THREE.OrbitControls
  // examples/js/loaders/GLTFLoader.js: THREE.GLTFLoader (the global build, like the page's
  // three.js; the module build under examples/jsm would need an import map).
  std::string gltf_loader;
};

// Reads the three files from `dir`. NotFound naming the missing file and the package to install;
// files over 8 MiB are refused (not three.js).
absl::StatusOr<ThreeJsFiles> LoadThreeJs(const std::string& dir);

}  // namespace plx::web

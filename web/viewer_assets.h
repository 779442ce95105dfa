// The viewer page's own files (web/viewer_assets/: index.html, viewer.js, viewer.css), compiled
// in by web/embed_assets.cmake: base name -> contents.
#pragma once

#include <map>
#include <string>

namespace plx::web {

const std::map<std::string, std::string>& EmbeddedAssets();

}  // namespace plx::web

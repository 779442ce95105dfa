// Map names on the wire (CreateMap, Track, Integrate, Slam, Export, ...).
#pragma once

#include <string>

#include "absl/status/status.h"

namespace plx {

// Valid map names: 1-64 characters of [A-Za-z0-9_.-], not starting with '.'.
absl::Status CheckMapName(const std::string& name, const std::string& field);

}  // namespace plx

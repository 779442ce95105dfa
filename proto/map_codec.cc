#include "proto/map_codec.h"

#include <cctype>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

absl::Status Invalid(const std::string& field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", what));
}

}  // namespace

absl::Status CheckMapName(const std::string& name, const std::string& field) {
  if (name.empty() || name.size() > 64 || name[0] == '.') {
    return Invalid(field, absl::StrCat("map names are 1-64 characters of [A-Za-z0-9_.-] not "
                                       "starting with '.', got \"", name, "\""));
  }
  for (char c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-')) {
      return Invalid(field, absl::StrCat("map names use [A-Za-z0-9_.-] only, got \"", name, "\""));
    }
  }
  return absl::OkStatus();
}

}  // namespace plx

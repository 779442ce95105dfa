#include "proto/map_codec.h"

#include <cctype>

#include "absl/strings/str_cat.h"
#include "core/mapping/mapper.h"

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

absl::StatusOr<float> VoxelSizeFromProto(float voxel_size, float default_size,
                                         const std::string& field) {
  // Only exactly 0 is the default: -0.1 or NaN is a mistake, not a request for the default.
  if (voxel_size == 0.0f) return default_size;
  if (!VoxelSizeInRange(voxel_size)) {
    return Invalid(field, absl::StrCat("must be in [", kMinVoxelSize, ", ", kMaxVoxelSize,
                                       "] metres (0 = the default), got ", voxel_size));
  }
  return voxel_size;
}

pb::MapInfo MapStatusToProto(const MapStatus& s) {
  pb::MapInfo info;
  info.set_name(s.name);
  info.set_voxel_size(s.voxel_size);
  info.set_version(s.version);
  info.set_bricks(static_cast<uint64_t>(s.bricks));
  info.set_memory_bytes(static_cast<uint64_t>(s.memory_bytes));
  info.set_keyframes(static_cast<uint32_t>(s.keyframes));
  info.set_dirty(s.dirty);
  info.set_mapping(s.mapping);
  info.set_source(s.source);
  return info;
}

}  // namespace plx

// What a map is when a program lists it: the daemon's GetMap/ListMaps (server/map_store.h,
// proto/map_codec.h), the viewer's map list (web/viewer_source.h) and `plenox view`'s. The
// grid's own numbers come from the map (MapStatusOf); the rest (the version, the keyframes, a
// pending save, a mapping job) is known only to whoever holds the map.
#pragma once

#include <cstdint>
#include <string>

#include "core/grid/plenoxel_map.h"

namespace plx {

struct MapStatus {
  std::string name;
  float voxel_size = 0.0f;
  uint64_t version = 0;  // published versions (readers see the newest)
  int64_t bricks = 0;
  int64_t memory_bytes = 0;
  int keyframes = 0;
  bool dirty = false;    // changed since it was last saved
  bool mapping = false;  // a mapping job (Integrate, SLAM) holds the writer lease
  std::string source;    // PlenoxelMap::source
};

// `map` under `name`: its voxel size, bricks, memory and source; the holder's fields are left
// at their defaults.
MapStatus MapStatusOf(const std::string& name, const PlenoxelMap& map);

}  // namespace plx

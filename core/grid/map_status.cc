#include "core/grid/map_status.h"

namespace plx {

MapStatus MapStatusOf(const std::string& name, const PlenoxelMap& map) {
  MapStatus status;
  status.name = name;
  status.voxel_size = map.grid.voxel_size();
  status.bricks = map.grid.num_bricks();
  status.memory_bytes = map.grid.Memory().total_bytes();
  status.source = map.source;
  return status;
}

}  // namespace plx

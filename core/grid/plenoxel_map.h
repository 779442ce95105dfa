// A map: the brick grid plus how it is meant to be rendered. This is what map files hold.
#pragma once

#include <string>

#include "core/grid/render_options.h"
#include "core/grid/sparse_grid.h"

namespace plx {

struct PlenoxelMap {
  explicit PlenoxelMap(float voxel_size) : grid(voxel_size) {}

  SparseGrid grid;
  RenderOptions render;   // thresholds, step and background the map was optimised with
  std::string source;     // free text: which dataset/frames built it (shown by tools)
};

}  // namespace plx

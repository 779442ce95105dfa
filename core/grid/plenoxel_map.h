// A map: the brick grid plus how it is meant to be rendered. This is what map files hold.
#pragma once

#include <string>

#include "core/grid/render_options.h"
#include "core/grid/sparse_grid.h"

namespace plx {

struct PlenoxelMap {
  explicit PlenoxelMap(float voxel_size) : grid(voxel_size) {}
  PlenoxelMap(SparseGrid grid, const RenderOptions& render, std::string source)
      : grid(std::move(grid)), render(render), source(std::move(source)) {}

  // Copy-on-write versions (see SparseGrid): Publish hands readers a version sharing every
  // brick with this map, which then clones a brick before changing it; ShareCopy starts a new
  // writer from a map that is no longer written (a published version).
  PlenoxelMap Publish() { return PlenoxelMap(grid.Publish(), render, source); }
  PlenoxelMap ShareCopy() const { return PlenoxelMap(grid.ShareCopy(), render, source); }

  SparseGrid grid;
  RenderOptions render;   // thresholds, step and background the map was optimised with
  std::string source;     // free text: which dataset/frames built it (shown by tools)
};

}  // namespace plx

// The offline mapping job over a dataset (the paper's protocol): load the chosen keyframes
// with their ground-truth poses, allocate and initialise, optimise.
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/formats/map_keyframe.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"
#include "core/mapping/mapper.h"

namespace plx {

struct MapDatasetProgress {
  int keyframes_loaded = 0;
  int keyframes_total = 0;
  bool optimizing = false;
  MappingProgress optimization;  // valid when optimizing
};

struct MapDatasetResult {
  std::unique_ptr<PlenoxelMap> map;
  MapKeyframes keyframes;  // the keyframes as the map file keeps them (poses, intrinsics)
  MappingSummary summary;
  double load_s = 0.0;
};

// Maps `keyframes` (dataset indices; each needs a ground-truth pose). `progress` may be null;
// returning false from it cancels (the result is then Cancelled).
absl::StatusOr<MapDatasetResult> MapDataset(
    const RgbdDataset& dataset, const std::vector<int>& keyframes, const MapperOptions& options,
    Backend& backend, const std::function<bool(const MapDatasetProgress&)>& progress = nullptr);

}  // namespace plx

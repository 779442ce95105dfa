// Map quality on held-out views (DESIGN.md §11): the map is rendered at each frame's
// ground-truth pose and compared with the measured colour and depth at random pixels that
// have valid depth.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"

namespace plx {

struct MapEvalOptions {
  int pixels_per_frame = 10000;  // sampled without replacement among valid-depth pixels; 0 = all
  double max_depth = 10.0;       // measured depth beyond this is not used
  uint32_t seed = 20230606;
};

struct MapEvalResult {
  double psnr = 0.0;              // dB, mean over frames, all sampled pixels; colour clamped
                                  // to [0, 1]
  double depth_l1_m = 0.0;        // mean |rendered range - measured range| over rendered pixels
  double depth_l1_median_m = 0.0; // median of the same errors
  double coverage = 0.0;          // fraction of sampled pixels the map renders (opacity >= 0.5)
  int frames = 0;
  int64_t pixels = 0;             // sampled pixels, all frames
};

// Evaluates `map` on dataset frames `frame_indices` (each must have ground truth).
absl::StatusOr<MapEvalResult> EvaluateMap(Backend& backend, const PlenoxelMap& map,
                                          const RgbdDataset& dataset,
                                          const std::vector<int>& frame_indices,
                                          const MapEvalOptions& options = {});

// Frames held out from mapping every `every`-th frame: those halfway between two keyframes
// (index % every == every / 2), at most `max_frames` of them evenly spread (0 = all).
std::vector<int> HeldOutFrames(int num_frames, int every, int max_frames = 0);

// Mapping frames: 0, every, 2 * every, ...
std::vector<int> KeyframeIndices(int num_frames, int every);

}  // namespace plx

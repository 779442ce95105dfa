#include "core/mapping/map_dataset.h"

#include <chrono>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mapping/map_keyframes_of.h"

namespace plx {

absl::StatusOr<MapDatasetResult> MapDataset(
    const RgbdDataset& dataset, const std::vector<int>& keyframes, const MapperOptions& options,
    Backend& backend, const std::function<bool(const MapDatasetProgress&)>& progress) {
  PLX_RETURN_IF_ERROR(Mapper::ValidateOptions(options));
  if (keyframes.empty()) return absl::InvalidArgumentError("no keyframes to map");
  const auto start = std::chrono::steady_clock::now();
  Mapper mapper(options, &backend);
  MapDatasetProgress state;
  state.keyframes_total = static_cast<int>(keyframes.size());
  for (int index : keyframes) {
    if (index < 0 || index >= dataset.size()) {
      return absl::OutOfRangeError(absl::StrCat("keyframe ", index, " is outside the dataset (",
                                                dataset.size(), " frames)"));
    }
    const std::optional<SE3> pose = dataset.ground_truth(index);
    if (!pose) {
      return absl::FailedPreconditionError(absl::StrCat(
          "frame ", index, " (t=", dataset.timestamp(index),
          ") has no ground-truth pose; mapping with known poses needs one for every keyframe"));
    }
    PLX_ASSIGN_OR_RETURN(RgbdFrame frame, dataset.LoadFrame(index));
    PLX_RETURN_IF_ERROR(mapper.AddKeyframe(std::move(frame), *pose, dataset.calibration().pinhole));
    ++state.keyframes_loaded;
    if (progress && !progress(state)) return absl::CancelledError("mapping cancelled");
  }
  MapDatasetResult result;
  result.load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  PLX_RETURN_IF_ERROR(mapper.AllocateAndInitialize());
  bool cancelled = false;
  state.optimizing = true;
  PLX_ASSIGN_OR_RETURN(result.summary, mapper.Optimize([&](const MappingProgress& p) {
    state.optimization = p;
    if (progress && !progress(state)) {
      cancelled = true;
      return false;
    }
    return true;
  }));
  if (cancelled) return absl::CancelledError("mapping cancelled");
  result.keyframes = MapKeyframesOf(mapper.training_set());
  result.map = mapper.ReleaseMap();
  result.map->source = absl::StrCat(dataset.name(), ": ", keyframes.size(), " keyframes");
  return result;
}

}  // namespace plx

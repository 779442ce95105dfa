#include "core/mapping/map_keyframes_of.h"

namespace plx {

MapKeyframes MapKeyframesOf(const TrainingSet& set) {
  MapKeyframes out;
  out.reserve(static_cast<size_t>(set.num_frames()));
  for (int i = 0; i < set.num_frames(); ++i) {
    MapKeyframe k;
    k.timestamp = set.frame(i).timestamp;
    k.pose = set.pose(i);
    k.intrinsics = set.intrinsics(i);
    out.push_back(std::move(k));
  }
  return out;
}

}  // namespace plx

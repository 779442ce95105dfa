// The keyframes a mapping session has integrated, as a map file keeps them
// (core/formats/map_keyframe.h): what the daemon publishes beside each version so that the
// version's file carries them (Integrate streams, SLAM jobs).
#pragma once

#include "core/formats/map_keyframe.h"
#include "core/mapping/training_set.h"

namespace plx {

// Every frame of `set` in order: its timestamp, pose (as mapping refined it) and intrinsics,
// without features (SLAM attaches the ones it extracted; SlamCoordinator).
MapKeyframes MapKeyframesOf(const TrainingSet& set);

}  // namespace plx

// A camera's poses in the main map's frame, as far as its segments joined it (docs/SLAM.md,
// "Map segments"): a pose given in a segment that later joined the main map maps into it by
// that join's main_T_segment; poses of a segment that never joined stay in its own frame.
#pragma once

#include <map>
#include <vector>

#include "core/geometry/se3.h"
#include "core/geometry/stamped_pose.h"
#include "core/slam/slam_tracker.h"

namespace plx {

// The joins among one camera's results (in order): joined segment -> main_T_segment. A join
// is the frame with main_T_segment set; the segment it joined is the one the frame before
// was in.
std::map<int, SE3> SegmentJoins(const std::vector<SlamFrameResult>& results);

// Every result's pose, in the main map where its segment joined it (SegmentJoins).
std::vector<StampedPose> PosesInMainMap(const std::vector<SlamFrameResult>& results);

// Every result's pose in the main map's final frame (`plenox slam --corrected-out`): a frame
// anchored to a keyframe (SlamFrameResult::reference_keyframe) keeps its pose relative to it,
// moved to that keyframe's final pose (`keyframes`: the main map's, as refined and corrected at
// the end); the others as PosesInMainMap.
std::vector<StampedPose> CorrectedPoses(const std::vector<SlamFrameResult>& results,
                                        const std::vector<StampedPose>& keyframes);

// Every result's pose (as PosesInMainMap) moved through each of `corrections` (in generation
// order) newer than the frame it is in (SlamFrameResult::correction_generation; a segment's
// frames: the generation of the frame that joined it), by SlamCorrection::Move: the poses in
// the latest frame as a client that only sees the stream's corrections can hold them (`plenox
// --server ... slam --corrected-out`). A segment never joined keeps its own frame.
std::vector<StampedPose> FollowCorrections(const std::vector<SlamFrameResult>& results,
                                           const std::vector<SlamCorrection>& corrections);

}  // namespace plx

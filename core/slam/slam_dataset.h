// The SLAM job over a dataset (`plenox slam`, the demo, the benchmark): every frame through a
// SlamSession, no ground truth used except, when the dataset has it, frame 0's pose as the
// starting pose (so the trajectory lands in the ground-truth frame, as `plenox track` does).
//
// Replay: by default every frame is processed in order, as fast as the engine goes. `realtime`
// replays the frames at their timestamps (scaled by `speed`) as a live sensor would: after
// each frame the next one processed is the newest one whose time has come, and the frames
// skipped on the way are dropped (latest wins).
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/formats/map_keyframe.h"
#include "core/geometry/stamped_pose.h"
#include "core/slam/slam_session.h"

namespace plx {

struct SlamDatasetOptions {
  SlamOptions slam = DefaultSlamOptions();
  bool start_from_ground_truth = true;
  bool realtime = false;
  double speed = 1.0;  // realtime replay speed (2 = twice as fast as recorded)
  int max_frames = 0;  // 0 = every frame
  // How often `finishing` (RunSlamOnDataset) hears how the final mapping goes (seconds).
  double finishing_report_s = 1.0;
};

struct SlamDatasetResult {
  // One pose per processed frame, in the main map's frame where known (PosesInMainMap: a
  // segment's poses once it joined); results[i].pose is the pose as given online.
  std::vector<StampedPose> trajectory;
  std::vector<SlamFrameResult> results;    // per processed frame
  std::vector<StampedPose> keyframes;      // final (refined) keyframe poses
  std::vector<LoopEdge> loops;             // the map's loop edges at the end (keyframe indices)
  std::shared_ptr<const PlenoxelMap> map;  // the final version
  std::shared_ptr<const MapKeyframes> map_keyframes;  // its keyframes, as a map file keeps them
  SlamProgress progress;
  bool started_from_ground_truth = false;
  int frames = 0;   // in the dataset (up to max_frames)
  int dropped = 0;  // realtime: skipped because the tracker was behind
  double ms_per_frame_median = 0.0;  // ProcessFrame time, image decoding excluded
  double ms_per_frame_p95 = 0.0;
  double wall_s = 0.0;               // first frame to the final map, decoding included
  // First frame to the last frame's pose (decoding included, mapping running beside): what a
  // live camera sees. The rest of wall_s is the final mapping (Finish).
  double stream_s = 0.0;
};

// `progress(result)` after every processed frame; returning false cancels. After the last
// frame the session finishes its map (the iterations mapping still owes, a loop correction's
// rebuild: on a long run minutes); `finishing(progress)` hears how that goes, once when it
// starts, every options.finishing_report_s while it runs, and once when it is done.
// `streamed(result)` is called once after the last frame, before the map is finished, with
// what the stream decided (trajectory, results, frames, dropped, stream_s; the rest is filled
// in at the end): the online trajectory is final then, so a caller can keep it before minutes
// of finishing that an interrupt would lose.
absl::StatusOr<SlamDatasetResult> RunSlamOnDataset(
    const RgbdDataset& dataset, Backend& tracking_backend,
    const SlamSession::BackendFactory& make_mapping_backend, const SlamDatasetOptions& options,
    const std::function<bool(const SlamFrameResult&)>& progress = nullptr,
    const std::function<void(const SlamProgress&)>& finishing = nullptr,
    const std::function<void(const SlamDatasetResult&)>& streamed = nullptr);

}  // namespace plx

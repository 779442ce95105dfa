#include "server/daemon_viewer_source.h"

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>

#include "core/common/allocation_guard.h"
#include "server/slam_job.h"

namespace plx::server {

std::vector<MapStatus> DaemonViewerSource::ListMaps() const { return state_->maps->List(); }

absl::StatusOr<web::ViewerMap> DaemonViewerSource::Latest(const std::string& name) const {
  absl::StatusOr<MapVersion> latest = state_->maps->Latest(name);
  if (!latest.ok()) return latest.status();
  if (latest->map == nullptr) {
    return absl::NotFoundError("map \"" + name + "\" has no published version yet");
  }
  return web::ViewerMap{latest->map, latest->version, latest->keyframes};
}

absl::StatusOr<web::ViewerTrajectories> DaemonViewerSource::Trajectories(
    const std::string& name) const {
  absl::StatusOr<MapStatus> info = state_->maps->Info(name);
  if (!info.ok()) return info.status();
  web::ViewerTrajectories out;
  out.map_version = info->version;
  if (const std::shared_ptr<SlamJob> job = state_->slam_jobs->RunningOn(name)) {
    const SlamJobStatus s = job->Status();
    out.slam_running = !s.finished;
    out.keyframes_integrated = s.mapping.keyframes_integrated;
  }
  if (const std::shared_ptr<const TrajectoryRecord> record = state_->slam_jobs->Trajectory(name)) {
    out.cameras = record->Cameras();
    out.keyframes = record->Keyframes();
    out.loops = record->Loops();
    if (!out.slam_running) out.keyframes_integrated = static_cast<int>(out.keyframes.size());
  }
  return out;
}

absl::Status DaemonViewerSource::RunOnDevice(const DeviceWork& work, absl::Duration timeout) {
  if (state_->draining.load()) return absl::UnavailableError("plenoxd is shutting down");
  // Shared with the task. `work` may refer to the caller's stack, so it never runs after this
  // function returned: a task still queued at the deadline skips it, and a running one is told
  // to stop (`cancelled`, checked between a render's row tiles) and waited for.
  struct Call {
    std::mutex mutex;
    std::condition_variable done_cv;
    bool started = false;
    bool done = false;
    bool abandoned = false;
    std::atomic<bool> cancelled{false};
    absl::Status result;
  };
  auto call = std::make_shared<Call>();
  DeviceWorker& worker = state_->workers->Pick(Priority::kInteractive);
  worker.Post(Priority::kInteractive, [call, &work](Backend* backend, bool stopped) {
    {
      std::lock_guard<std::mutex> lock(call->mutex);
      if (call->abandoned) return;  // the caller is gone, and so may `work` be
      call->started = true;
    }
    absl::Status result = absl::UnavailableError("plenoxd is shutting down");
    if (!stopped) {
      result = CatchAllocationFailure("viewer", [&]() -> absl::Status {
        return work(*backend, [call] { return call->cancelled.load(); });
      });
    }
    std::lock_guard<std::mutex> lock(call->mutex);
    call->result = std::move(result);
    call->done = true;
    call->done_cv.notify_all();
  });
  std::unique_lock<std::mutex> lock(call->mutex);
  const bool finished =
      call->done_cv.wait_for(lock, std::chrono::microseconds(absl::ToInt64Microseconds(timeout)),
                             [&] { return call->done; });
  if (finished) return call->result;
  call->abandoned = true;
  if (call->started) {
    call->cancelled = true;
    call->done_cv.wait(lock, [&] { return call->done; });
  }
  return absl::DeadlineExceededError("the device did not finish in time (it is busy)");
}

}  // namespace plx::server

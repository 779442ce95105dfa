// What the viewer (web/viewer_routes.h) reads, and where it computes: an interface the two
// programs implement. plenoxd's (server/daemon_viewer_source.h) reads its map store and its SLAM
// streams' trajectory records and runs renders on a device worker; `plenox view`'s
// (clients/plenox) holds one map file and runs them on its own backend. The routes never see
// either program.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/se3.h"
#include "core/grid/map_status.h"
#include "core/formats/map_keyframe.h"
#include "core/grid/plenoxel_map.h"
#include "core/kernels/backend.h"

namespace plx::web {

// A published, immutable map version.
struct ViewerMap {
  std::shared_ptr<const PlenoxelMap> map;
  uint64_t version = 0;
  // The version's keyframes (their poses make the observed surface's mesh); null: none.
  std::shared_ptr<const MapKeyframes> keyframes;
};

// One camera (a Slam stream) on a map: where it is now and the way it came, thinned to a bounded
// number of positions (server/trajectory_record.h).
struct CameraTrack {
  int id = 0;               // per map, in the order the streams joined
  std::string label;        // the frames' camera_id, or "camera <id>"
  bool active = false;      // its stream is still open
  std::string state;        // the last frame's: OK, DEGRADED, LOST, RELOCALISED (WAITING: none yet)
  int64_t frames = 0;       // frames tracked
  double timestamp = 0.0;   // of the last frame
  SE3 pose;                 // world_T_camera of the last frame
  std::vector<Eigen::Vector3d> path;  // camera centres, oldest first, ending at `pose`
};

// A map's SLAM activity: its streams' cameras and its job's keyframes.
struct ViewerTrajectories {
  bool slam_running = false;    // a SLAM job maps it now
  int keyframes_integrated = 0;
  uint64_t map_version = 0;
  std::vector<CameraTrack> cameras;
  std::vector<SE3> keyframes;   // refined keyframe poses (newest kept when over the bound)
  // Loop-closure edges (docs/SLAM.md, "Loop closure"): indices into `keyframes`.
  std::vector<std::pair<int, int>> loops;
};

class ViewerSource {
 public:
  virtual ~ViewerSource() = default;

  // Shown in the page's title: "plenoxd 0.1.0", "plenox view room.plx".
  virtual std::string Title() const = 0;
  // The maps, as plenoxd's ListMaps lists them (without gRPC).
  virtual std::vector<MapStatus> ListMaps() const = 0;
  // The newest published version; NotFound for an unknown map.
  virtual absl::StatusOr<ViewerMap> Latest(const std::string& name) const = 0;
  // NotFound for an unknown map; a map without SLAM streams has no cameras.
  virtual absl::StatusOr<ViewerTrajectories> Trajectories(const std::string& name) const = 0;
  // Runs `work` on the source's compute device (plenoxd: a device worker at interactive
  // priority; plenox view: its one backend, one call at a time) and returns its status, within
  // `timeout`: DEADLINE_EXCEEDED after it, while `cancelled` turns true so the work stops at
  // its next check (its result is then dropped). Called from HTTP pool threads; the caller
  // bounds the work (a render's size, a mesh's triangles).
  using DeviceWork =
      std::function<absl::Status(Backend& backend, const std::function<bool()>& cancelled)>;
  virtual absl::Status RunOnDevice(const DeviceWork& work, absl::Duration timeout) = 0;
};

}  // namespace plx::web

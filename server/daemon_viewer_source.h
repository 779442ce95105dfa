// The web viewer's view of plenoxd (web/viewer_source.h): the map store's maps and published
// versions, the SLAM jobs' trajectory records, and the viewer's device work (renders) posted to
// a device worker at interactive priority like the Render RPC's. Read directly in the server
// layer, never through gRPC to the daemon itself.
#pragma once

#include <string>
#include <vector>

#include "server/daemon_state.h"
#include "web/viewer_source.h"

namespace plx::server {

class DaemonViewerSource final : public web::ViewerSource {
 public:
  // `state` must outlive the source.
  DaemonViewerSource(DaemonState* state, std::string title)
      : state_(state), title_(std::move(title)) {}

  std::string Title() const override { return title_; }
  std::vector<MapStatus> ListMaps() const override;
  absl::StatusOr<web::ViewerMap> Latest(const std::string& name) const override;
  absl::StatusOr<web::ViewerTrajectories> Trajectories(const std::string& name) const override;
  absl::Status RunOnDevice(const DeviceWork& work, absl::Duration timeout) override;

 private:
  DaemonState* const state_;
  const std::string title_;
};

}  // namespace plx::server

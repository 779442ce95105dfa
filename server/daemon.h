// plenoxd's runtime: the map store, device workers, the gRPC server (plenoxd.v1, health,
// reflection), metrics, and an orderly drain. main.cc parses flags into DaemonOptions; tests
// start a Daemon in-process on a free port.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "app/make_backend.h"
#include "core/formats/snapshot_policy.h"
#include "core/storage/lease_policy.h"
#include "server/daemon_state.h"
#include "server/lease_keeper.h"
#include "server/metrics.h"
#include "server/plenoxd_service.h"
#include "server/slam_job.h"
#include "server/snapshot_scheduler.h"
#include "web/three_js.h"

// The HTTP side (web/): defined in daemon.cc's includes, so the daemon's users do not compile
// the viewer's headers.
namespace plx::web {
class HttpServer;
class Viewer;
class ViewerSource;
}  // namespace plx::web

namespace plx::server {

struct DaemonOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 picks a free one
  std::string data_dir;                    // maps are loaded from and saved to here
  // Shared map storage instead of data_dir (one of the two): a directory on a volume several
  // daemons mount. Maps are loaded when a call names them and written only under their lease
  // (server/map_store.h, core/storage/lease_policy.h), which lasts lease_term.
  std::string shared_dir;
  absl::Duration lease_term = absl::Seconds(kDefaultLeaseSeconds);
  // Maps with unsaved changes are saved in the background once their oldest unsaved change is
  // this old (server/snapshot_scheduler.h; needs data_dir). Zero: only SaveMap and the drain
  // save.
  absl::Duration snapshot_interval = absl::Seconds(kDefaultSnapshotSeconds);
  std::string auth_token;                  // empty: no authentication
  std::string tls_cert_pem, tls_key_pem;   // both empty: plaintext
  int metrics_port = -1;                   // < 0: off; 0: a free port
  std::string metrics_host = "127.0.0.1";
  // The web viewer (web/viewer_routes.h) at /viewer/ on the metrics port (which it needs);
  // three.js is read from viewer_three_dir at Start (Debian's libjs-three).
  bool viewer = false;
  std::string viewer_three_dir = web::kDefaultThreeJsDir;
  int max_maps = 16;
  int64_t max_map_bytes = int64_t{4} << 30;
  int max_streams = 32;
  int max_message_bytes = 64 << 20;
  // Pixels (width x height) of one Track/Integrate frame; larger frames are RESOURCE_EXHAUSTED
  // before their images are decoded. 4K UHD: a decoded frame (float colour + depth) is 133 MB.
  int64_t max_frame_pixels = 3840 * 2160;
  int64_t max_render_pixels = kDefaultMaxRenderPixels;  // width * height of one Render
  int threads = 0;                         // CPU backend threads (0 = all cores)
  // The CPU backend only: a second CPU worker for mapping (Integrate, SLAM jobs, Export) beside
  // the one for tracking and rendering, both with `threads` threads, the mapping one's at
  // `mapping_nice` (0-19) steps lower OS priority (server/device_worker.h). Off: one worker
  // does both, mapping in chunks between frames.
  bool mapping_worker = true;
  int mapping_nice = 10;
  // Compute devices, one worker each: kCpu one CPU worker; kCuda one worker per GPU in `gpus`
  // (Start fails when there is none); kAuto like kCuda when a GPU is visible, else kCpu.
  BackendKind backend = BackendKind::kAuto;
  std::optional<std::vector<int>> gpus;    // CUDA device ids (ParseGpuList); nullopt = all
  // TEST ONLY: every map save first sleeps this long (MapStoreOptions::test_only_save_delay);
  // main.cc sets it from $PLENOXD_TEST_ONLY_SAVE_DELAY_S for the stop watchdog's test.
  absl::Duration test_only_save_delay = absl::ZeroDuration();
};

// The version GetServerInfo reports (the CMake project's VERSION).
std::string PlenoxdVersion();

class Daemon {
 public:
  static absl::StatusOr<std::unique_ptr<Daemon>> Start(const DaemonOptions& options);
  ~Daemon();

  int port() const { return port_; }
  int metrics_port() const;

  // Stops taking calls (health NOT_SERVING, new calls UNAVAILABLE), lets running calls finish
  // for up to `grace` and cancels the rest, stops the workers and saves every dirty map, logging
  // a map_not_saved line for each that could not be saved. Returns an error naming them all
  // (the first one's code) when any failed. Safe to call twice. Not bounded in time by itself:
  // plenoxd's main bounds it with a StopWatchdog (server/stop_watchdog.h).
  absl::Status Drain(absl::Duration grace);

  // Maps changed since they were last saved (for the stop watchdog's last words).
  std::vector<std::string> UnsavedMaps() const;

  DaemonState& state() { return state_; }
  std::string RenderMetrics() const;

 private:
  Daemon();

  DaemonOptions options_;
  std::unique_ptr<MapStore> maps_;
  std::unique_ptr<WorkerPool> workers_;
  std::unique_ptr<DeviceWorker> io_;  // file I/O: a DeviceWorker without a backend
  std::unique_ptr<JobRegistry> jobs_;
  std::unique_ptr<Metrics> metrics_registry_;
  // Snapshots: their worker (one save at a time, at --mapping-nice), and the timer that posts
  // to it, destroyed first.
  std::unique_ptr<DeviceWorker> snapshot_worker_;
  std::unique_ptr<SnapshotScheduler> snapshots_;
  std::unique_ptr<LeaseKeeper> leases_;  // --shared-dir: renews the maps' leases
  DaemonState state_;
  // Destroyed before the state and the workers it uses (a job detaches from its worker).
  std::unique_ptr<SlamJobs> slam_jobs_;
  std::unique_ptr<PlenoxdService> service_;
  std::unique_ptr<grpc::Server> server_;
  // --viewer: what the viewer's routes use; destroyed after the HTTP server that calls them.
  std::unique_ptr<web::ViewerSource> viewer_source_;
  std::unique_ptr<web::Viewer> viewer_;
  std::unique_ptr<web::HttpServer> http_;  // --metrics-port: /metrics (and --viewer: /viewer/)
  int port_ = 0;
  bool drained_ = false;
};

}  // namespace plx::server

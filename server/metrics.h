// Daemon metrics in the Prometheus text format (served at /metrics on the --metrics-port
// HttpServer): counters and a tracking-latency histogram updated by the handlers, gauges read
// when scraped.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "web/http_server.h"

namespace plx::server {

// A Prometheus histogram of latencies in seconds (10 ms to 5 s buckets).
class LatencyHistogram {
 public:
  void Observe(double seconds);
  void Render(const char* name, const char* help, std::string* out) const;

 private:
  static constexpr std::array<double, 10> kBuckets = {0.01, 0.025, 0.05, 0.1, 0.15,
                                                       0.25, 0.5,   1.0,  2.5, 5.0};
  std::array<std::atomic<int64_t>, kBuckets.size() + 1> counts_{};
  std::atomic<int64_t> micros_sum_{0};
};

class Metrics {
 public:
  std::atomic<int64_t> frames_tracked{0};
  std::atomic<int64_t> frames_dropped{0};
  std::atomic<int64_t> frames_lost{0};
  std::atomic<int64_t> keyframes_integrated{0};
  std::atomic<int64_t> renders{0};
  std::atomic<int64_t> rpc_errors{0};
  std::atomic<int64_t> active_streams{0};
  std::atomic<int64_t> slam_streams{0};    // Slam streams on a job
  std::atomic<int64_t> slam_keyframes{0};  // keyframes Slam streams handed to their jobs
  // Background saves (server/snapshot_scheduler.h): maps written, bytes written, failures.
  std::atomic<int64_t> snapshots{0};
  std::atomic<int64_t> snapshot_bytes{0};
  std::atomic<int64_t> snapshot_failures{0};

  void ObserveTrackLatency(double seconds) { track_latency_.Observe(seconds); }
  // A frame a Slam stream processed: `state` is its SlamState's index (OK, DEGRADED, LOST,
  // RELOCALISED, WAITING), `seconds` from receiving it to its update.
  void ObserveSlamFrame(int state, double seconds);
  // How long a snapshot took to write its file.
  void ObserveSnapshot(double seconds) { snapshot_latency_.Observe(seconds); }

  // Gauges supplied by the daemon at scrape time.
  struct Gauges {
    int64_t maps = 0;
    int64_t map_bytes = 0;
    int64_t queue_depth = 0;
    int64_t jobs_running = 0;
    bool serving = true;
    // Running SLAM mapping jobs, the keyframes they have accepted but not integrated yet
    // (mapping lag), and the longest of their last publishes.
    int64_t slam_jobs = 0;
    int64_t slam_pending_keyframes = 0;
    double slam_last_publish_s = 0.0;
    // Their loop closure (docs/SLAM.md, "Loop closure"), summed: loop edges in the pose
    // graphs, candidates rejected, corrected maps published; the slowest last graph solve.
    int64_t slam_loops = 0;
    int64_t slam_loops_rejected = 0;
    int64_t slam_corrections = 0;
    double slam_last_solve_s = 0.0;
    // Maps with changes not on disk, and the age of the oldest such change: what a crash would
    // lose now (bounded by --snapshot-seconds plus a save).
    int64_t unsaved_maps = 0;
    double unsaved_s = 0.0;
    // Shared storage (--shared-dir): maps held under a lease, maps dropped because another
    // daemon took their lease over, and saves the fence refused (nothing was written).
    int64_t leases_held = 0;
    int64_t lease_losses = 0;
    int64_t fenced_saves_refused = 0;
    // Handoffs: maps given up to a daemon that asked for them, and maps taken after their
    // holder released them for this one.
    int64_t handoffs_given = 0;
    int64_t handoffs_taken = 0;
    // One per compute worker: plenoxd_device_info{device, kind, name} 1 and, per device, the
    // tasks queued or running and the streams bound to it.
    struct Device {
      std::string id;    // "cpu", "cuda:0"
      std::string kind;  // "cpu", "cuda"
      std::string name;  // "cuda:0 NVIDIA H100 80GB HBM3 (sm_90, 79.1 GiB)"
      int64_t queue_depth = 0;
      int64_t streams = 0;
    };
    std::vector<Device> devices;
    // The metrics/viewer port itself (web/http_server.h): what its bounds turned away.
    web::HttpServerStats http;
  };
  std::string Render(const Gauges& gauges) const;

 private:
  LatencyHistogram track_latency_;
  LatencyHistogram slam_latency_;
  LatencyHistogram snapshot_latency_;
  std::array<std::atomic<int64_t>, 5> slam_frames_{};  // by state
};

// Serves `render()` (the Prometheus text) at GET /metrics on `server`.
void AddMetricsRoute(web::HttpServer& server, std::function<std::string()> render);

}  // namespace plx::server

// Daemon metrics in the Prometheus text format (served on --metrics-port): counters and a
// tracking-latency histogram updated by the handlers, gauges read when scraped.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace plx::server {

class Metrics {
 public:
  std::atomic<int64_t> frames_tracked{0};
  std::atomic<int64_t> frames_dropped{0};
  std::atomic<int64_t> frames_lost{0};
  std::atomic<int64_t> keyframes_integrated{0};
  std::atomic<int64_t> renders{0};
  std::atomic<int64_t> rpc_errors{0};
  std::atomic<int64_t> active_streams{0};

  void ObserveTrackLatency(double seconds);

  // Gauges supplied by the daemon at scrape time.
  struct Gauges {
    int64_t maps = 0;
    int64_t map_bytes = 0;
    int64_t queue_depth = 0;
    int64_t jobs_running = 0;
    bool serving = true;
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
  };
  std::string Render(const Gauges& gauges) const;

 private:
  static constexpr std::array<double, 10> kBuckets = {0.01, 0.025, 0.05, 0.1, 0.15,
                                                       0.25, 0.5,   1.0,  2.5, 5.0};
  std::array<std::atomic<int64_t>, kBuckets.size() + 1> latency_counts_{};
  std::atomic<int64_t> latency_micros_sum_{0};
};

// A minimal HTTP/1.0 server answering GET /metrics (anything else: 404) on 127.0.0.1 or the
// given host. One connection at a time is plenty for a scraper.
class MetricsHttpServer {
 public:
  // Binds now; `port` 0 picks a free port (see port()).
  static std::unique_ptr<MetricsHttpServer> Start(const std::string& host, int port,
                                                  std::function<std::string()> render,
                                                  std::string* error);
  ~MetricsHttpServer();
  int port() const { return port_; }

 private:
  MetricsHttpServer(int fd, int port, std::function<std::string()> render);
  void Loop();

  int fd_;
  int port_;
  std::function<std::string()> render_;
  std::atomic<bool> stopping_{false};
  std::thread thread_;
};

}  // namespace plx::server

#include "server/metrics.h"

#include <iterator>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx::server {
namespace {

// A label value in the text format: backslash, double quote and newline escaped.
std::string LabelValue(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '"') {
      out += "\\\"";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

void LatencyHistogram::Observe(double seconds) {
  size_t bucket = 0;
  while (bucket < kBuckets.size() && seconds > kBuckets[bucket]) ++bucket;
  counts_[bucket].fetch_add(1, std::memory_order_relaxed);
  micros_sum_.fetch_add(static_cast<int64_t>(seconds * 1e6), std::memory_order_relaxed);
}

void LatencyHistogram::Render(const char* h, const char* help, std::string* out) const {
  absl::StrAppend(out, "# HELP ", h, " ", help, "\n", "# TYPE ", h, " histogram\n");
  int64_t cumulative = 0;
  for (size_t i = 0; i < kBuckets.size(); ++i) {
    cumulative += counts_[i].load();
    absl::StrAppend(out, h, "_bucket{le=\"", absl::StrFormat("%g", kBuckets[i]), "\"} ",
                    cumulative, "\n");
  }
  cumulative += counts_[kBuckets.size()].load();
  absl::StrAppend(out, h, "_bucket{le=\"+Inf\"} ", cumulative, "\n", h, "_sum ",
                  absl::StrFormat("%.6f", micros_sum_.load() / 1e6), "\n", h, "_count ",
                  cumulative, "\n");
}

void Metrics::ObserveSlamFrame(int state, double seconds) {
  if (state >= 0 && state < static_cast<int>(slam_frames_.size())) {
    slam_frames_[state].fetch_add(1, std::memory_order_relaxed);
  }
  slam_latency_.Observe(seconds);
}

std::string Metrics::Render(const Gauges& g) const {
  std::string out;
  auto counter = [&](const char* name, const char* help, int64_t value) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " counter\n", name, " ",
                    value, "\n");
  };
  auto gauge = [&](const char* name, const char* help, int64_t value) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " gauge\n", name, " ",
                    value, "\n");
  };
  auto seconds_gauge = [&](const char* name, const char* help, double seconds) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " gauge\n", name, " ",
                    absl::StrFormat("%.6f", seconds), "\n");
  };
  counter("plenoxd_frames_tracked_total", "Frames tracked.", frames_tracked.load());
  counter("plenoxd_frames_dropped_total", "Frames dropped by latest-wins tracking streams.",
          frames_dropped.load());
  counter("plenoxd_frames_lost_total", "Tracked frames whose state was LOST.", frames_lost.load());
  counter("plenoxd_keyframes_integrated_total", "Keyframes added to maps.",
          keyframes_integrated.load());
  counter("plenoxd_renders_total", "Render calls served.", renders.load());
  counter("plenoxd_rpc_errors_total", "RPCs that ended with a non-OK status.", rpc_errors.load());
  gauge("plenoxd_active_streams", "Open streaming RPCs.", active_streams.load());
  gauge("plenoxd_maps", "Maps held.", g.maps);
  gauge("plenoxd_map_bytes", "Bytes held by all maps.", g.map_bytes);
  gauge("plenoxd_queue_depth", "Tasks queued or running on the device workers.", g.queue_depth);
  gauge("plenoxd_jobs_running", "Mapping jobs running.", g.jobs_running);
  gauge("plenoxd_serving", "1 while serving, 0 while draining.", g.serving ? 1 : 0);
  // Per compute device (one worker each): what it is, and how busy.
  absl::StrAppend(&out,
                  "# HELP plenoxd_device_info Compute devices, one worker each (value 1; "
                  "kind cpu or cuda, name the model).\n# TYPE plenoxd_device_info gauge\n");
  for (const Gauges::Device& d : g.devices) {
    absl::StrAppend(&out, "plenoxd_device_info{device=\"", LabelValue(d.id), "\",kind=\"",
                    LabelValue(d.kind), "\",name=\"", LabelValue(d.name), "\"} 1\n");
  }
  absl::StrAppend(&out,
                  "# HELP plenoxd_device_queue_depth Tasks queued or running on each device.\n"
                  "# TYPE plenoxd_device_queue_depth gauge\n");
  for (const Gauges::Device& d : g.devices) {
    absl::StrAppend(&out, "plenoxd_device_queue_depth{device=\"", LabelValue(d.id), "\"} ",
                    d.queue_depth, "\n");
  }
  absl::StrAppend(&out,
                  "# HELP plenoxd_device_streams Track, Integrate and Slam streams (and SLAM jobs) "
                  "bound to each device.\n# TYPE plenoxd_device_streams gauge\n");
  for (const Gauges::Device& d : g.devices) {
    absl::StrAppend(&out, "plenoxd_device_streams{device=\"", LabelValue(d.id), "\"} ",
                    d.streams, "\n");
  }
  track_latency_.Render("plenoxd_track_latency_seconds",
                        "Time from receiving a frame to its pose estimate.", &out);
  // SLAM: streams, frames by state, keyframes, the jobs' mapping lag and publish time.
  gauge("plenoxd_slam_streams", "Open Slam streams.", slam_streams.load());
  absl::StrAppend(&out,
                  "# HELP plenoxd_slam_frames_total Frames Slam streams processed, by state.\n"
                  "# TYPE plenoxd_slam_frames_total counter\n");
  static constexpr const char* kStates[] = {"ok", "degraded", "lost", "relocalised", "waiting"};
  static_assert(std::size(kStates) == std::tuple_size_v<decltype(slam_frames_)>);
  for (size_t i = 0; i < slam_frames_.size(); ++i) {
    absl::StrAppend(&out, "plenoxd_slam_frames_total{state=\"", kStates[i], "\"} ",
                    slam_frames_[i].load(), "\n");
  }
  counter("plenoxd_slam_keyframes_total", "Keyframes Slam streams handed to mapping.",
          slam_keyframes.load());
  gauge("plenoxd_slam_jobs", "Running SLAM mapping jobs.", g.slam_jobs);
  gauge("plenoxd_slam_pending_keyframes",
        "Keyframes accepted by SLAM jobs and not integrated yet (mapping lag).",
        g.slam_pending_keyframes);
  seconds_gauge("plenoxd_slam_last_publish_seconds",
                "The longest last publish of the running SLAM jobs.", g.slam_last_publish_s);
  gauge("plenoxd_slam_loops", "Loop edges in the running SLAM jobs' pose graphs.", g.slam_loops);
  gauge("plenoxd_slam_loops_rejected",
        "Loop candidates the running SLAM jobs rejected (a failed check or the pose graph).",
        g.slam_loops_rejected);
  gauge("plenoxd_slam_corrections",
        "Loop-closure corrections (rebuilt maps) the running SLAM jobs published.",
        g.slam_corrections);
  seconds_gauge("plenoxd_slam_last_solve_seconds",
                "The slowest last pose-graph solve of the running SLAM jobs.",
                g.slam_last_solve_s);
  slam_latency_.Render("plenoxd_slam_latency_seconds",
                       "Time from receiving a Slam frame to its update.", &out);
  // Persistence: what is not on disk yet, and the background saves that bound it.
  gauge("plenoxd_unsaved_maps", "Maps with changes not saved to the data dir.", g.unsaved_maps);
  seconds_gauge("plenoxd_unsaved_seconds",
                "Age of the oldest change not saved to the data dir (0: every map is saved).",
                g.unsaved_s);
  counter("plenoxd_snapshots_total", "Maps saved in the background (--snapshot-seconds).",
          snapshots.load());
  counter("plenoxd_snapshot_bytes_total", "Bytes of map files written by snapshots.",
          snapshot_bytes.load());
  counter("plenoxd_snapshot_failures_total", "Snapshots that failed (logged; tried again).",
          snapshot_failures.load());
  snapshot_latency_.Render("plenoxd_snapshot_seconds", "Time a snapshot took to write its file.",
                           &out);
  gauge("plenoxd_leases_held", "Maps held under a lease in shared storage (--shared-dir).",
        g.leases_held);
  counter("plenoxd_lease_losses_total",
          "Maps dropped because another daemon took their lease over.", g.lease_losses);
  counter("plenoxd_fenced_saves_refused_total",
          "Saves refused because the map's lease had passed to another daemon (nothing written).",
          g.fenced_saves_refused);
  counter("plenoxd_handoffs_given_total",
          "Maps saved and released for another daemon that asked for them (a ring change).",
          g.handoffs_given);
  counter("plenoxd_handoffs_taken_total",
          "Maps loaded after another daemon released them for this one.", g.handoffs_taken);
  // The HTTP port's bounds at work: a rising refusal or timeout count is a client (or an
  // attacker) the port turned away.
  gauge("plenoxd_http_connections_open", "Open connections to the metrics/viewer port.",
        g.http.connections_open);
  counter("plenoxd_http_connections_refused_total",
          "Connections refused over the per-client or total connection limit.",
          g.http.connections_refused);
  counter("plenoxd_http_requests_busy_total",
          "HTTP requests answered 503 because every handler thread was busy and the queue full.",
          g.http.requests_refused_busy);
  counter("plenoxd_http_timeouts_total",
          "HTTP connections closed by the request, idle or send deadline.", g.http.timeouts);
  return out;
}

void AddMetricsRoute(web::HttpServer& server, std::function<std::string()> render) {
  server.Get("/metrics", [render = std::move(render)] {
    return web::HttpResponse{200, "text/plain; version=0.0.4", render()};
  });
}

}  // namespace plx::server

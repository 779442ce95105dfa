#include "server/metrics.h"

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

void Metrics::ObserveTrackLatency(double seconds) {
  size_t bucket = 0;
  while (bucket < kBuckets.size() && seconds > kBuckets[bucket]) ++bucket;
  latency_counts_[bucket].fetch_add(1, std::memory_order_relaxed);
  latency_micros_sum_.fetch_add(static_cast<int64_t>(seconds * 1e6), std::memory_order_relaxed);
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
                  "# HELP plenoxd_device_streams Track and Integrate streams bound to each "
                  "device.\n# TYPE plenoxd_device_streams gauge\n");
  for (const Gauges::Device& d : g.devices) {
    absl::StrAppend(&out, "plenoxd_device_streams{device=\"", LabelValue(d.id), "\"} ",
                    d.streams, "\n");
  }
  const char* h = "plenoxd_track_latency_seconds";
  absl::StrAppend(&out, "# HELP ", h, " Time from receiving a frame to its pose estimate.\n",
                  "# TYPE ", h, " histogram\n");
  int64_t cumulative = 0;
  for (size_t i = 0; i < kBuckets.size(); ++i) {
    cumulative += latency_counts_[i].load();
    absl::StrAppend(&out, h, "_bucket{le=\"", absl::StrFormat("%g", kBuckets[i]), "\"} ",
                    cumulative, "\n");
  }
  cumulative += latency_counts_[kBuckets.size()].load();
  absl::StrAppend(&out, h, "_bucket{le=\"+Inf\"} ", cumulative, "\n", h, "_sum ",
                  absl::StrFormat("%.6f", latency_micros_sum_.load() / 1e6), "\n", h, "_count ",
                  cumulative, "\n");
  return out;
}

void AddMetricsRoute(HttpServer& server, std::function<std::string()> render) {
  server.Get("/metrics", [render = std::move(render)] {
    return HttpResponse{200, "text/plain; version=0.0.4", render()};
  });
}

}  // namespace plx::server

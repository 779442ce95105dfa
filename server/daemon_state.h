// What every RPC handler shares: the map store, the workers, jobs, metrics and the daemon's
// settings. Owned by Daemon (daemon.h); handlers only borrow it.
#pragma once

#include <atomic>
#include <cstdint>
#include <limits>
#include <string>

#include <grpcpp/server_context.h>

#include "absl/status/status.h"
#include "server/device_worker.h"
#include "server/jobs.h"
#include "server/map_store.h"
#include "server/metrics.h"

namespace plx::server {

class SlamJobs;  // server/slam_job.h

// Pixels one Render may ask for (--max-render-pixels): a 4K view (3840 x 2160). Rendering is
// cut into row tiles and stops when the call is cancelled, but a view this size still holds a
// CPU worker for seconds and needs ~20 bytes per pixel besides the encoded images.
inline constexpr int64_t kDefaultMaxRenderPixels = int64_t{3840} * 2160;

struct DaemonConfig {
  std::string auth_token;   // empty: no authentication
  int max_streams = 32;     // concurrent streaming RPCs (server/stream_slot.h)
  // Largest frame (intrinsics width x height) Track and Integrate accept; checked before any
  // image is decoded (DaemonOptions::max_frame_pixels).
  int64_t max_frame_pixels = 3840 * 2160;
  int64_t max_render_pixels = kDefaultMaxRenderPixels;  // per Render call
  // The largest message sent or received (--max-message-mb): a Render whose response could be
  // larger is refused before it renders (proto/render_size.h).
  int64_t max_message_bytes = 64 << 20;
  // For GetServerInfo.
  std::string version;      // plenoxd's version (PLX_VERSION)
  std::string backend;      // --backend: "cpu", "cuda" or "auto"
  bool cuda_built = false;  // this binary has the CUDA backend
};

struct DaemonState {
  MapStore* maps = nullptr;
  WorkerPool* workers = nullptr;
  DeviceWorker* io = nullptr;  // file I/O (save/load), off the compute workers
  JobRegistry* jobs = nullptr;
  Metrics* metrics = nullptr;
  SlamJobs* slam_jobs = nullptr;  // the maps' running SLAM mapping jobs
  DaemonConfig config;
  std::atomic<bool> draining{false};
  // When a drain's grace ends and gRPC cancels the calls still running (absl::ToUnixNanos);
  // set before `draining`. Tells the daemon's own cancellations from its clients'.
  std::atomic<int64_t> drain_deadline_ns{std::numeric_limits<int64_t>::max()};
};

// Every plenoxd.v1 call starts here: UNAVAILABLE while draining, UNAUTHENTICATED without the
// bearer token (metadata "authorization: Bearer <token>") when auth is on.
absl::Status CheckCall(const DaemonState& state, const grpc::CallbackServerContext* context);

// Why gRPC cancelled a call, for its status and log line: CANCELLED "cancelled: plenoxd is
// shutting down ..." when the drain's grace ended (the daemon cancelled it), "cancelled: the
// call's deadline passed" when it had, else `otherwise` (the client cancelled or went away).
absl::Status CancelledCallStatus(const DaemonState& state,
                                 const grpc::CallbackServerContext* context,
                                 const char* otherwise = "cancelled by the client");

// Whether a call's task, now taken from a worker's queue, should still run: UNAVAILABLE when
// the worker stopped (the daemon drains), CANCELLED when the call was cancelled while it was
// queued (client gone, deadline passed: nobody would read the result), else OK.
absl::Status QueuedCallStatus(bool worker_stopped, const grpc::CallbackServerContext* context);

}  // namespace plx::server

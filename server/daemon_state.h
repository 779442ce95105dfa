// What every RPC handler shares: the map store, the workers, jobs, metrics and the daemon's
// settings. Owned by Daemon (daemon.h); handlers only borrow it.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include <grpcpp/server_context.h>

#include "absl/status/status.h"
#include "server/device_worker.h"
#include "server/jobs.h"
#include "server/map_store.h"
#include "server/metrics.h"

namespace plx::server {

struct DaemonConfig {
  std::string auth_token;   // empty: no authentication
  int max_streams = 32;     // concurrent streaming RPCs
  // Largest frame (intrinsics width x height) Track and Integrate accept; checked before any
  // image is decoded (DaemonOptions::max_frame_pixels).
  int64_t max_frame_pixels = 3840 * 2160;
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
  DaemonConfig config;
  std::atomic<bool> draining{false};
};

// Every plenoxd.v1 call starts here: UNAVAILABLE while draining, UNAUTHENTICATED without the
// bearer token (metadata "authorization: Bearer <token>") when auth is on.
absl::Status CheckCall(const DaemonState& state, const grpc::CallbackServerContext* context);

// For streams: CheckCall plus the concurrent-stream limit; on OK the caller owns one stream slot
// and must ReleaseStreamSlot when the stream ends.
absl::Status AcquireStreamSlot(DaemonState& state, const grpc::CallbackServerContext* context);
void ReleaseStreamSlot(DaemonState& state);

}  // namespace plx::server

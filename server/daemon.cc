#include "server/daemon.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/server_builder.h>

#include <unistd.h>

#include <algorithm>
#include <climits>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "core/common/status_macros.h"
#include "core/cpu/cpu_backend.h"
#include "core/storage/directory_storage.h"
#include "server/daemon_viewer_source.h"
#include "server/log.h"
#include "server/secret_files.h"
#include "web/http_server.h"
#include "web/viewer_routes.h"
#include "web/viewer_source.h"

#ifndef PLX_VERSION
#define PLX_VERSION "unknown"
#endif

namespace plx::server {
namespace {

// Turns the reflection service on or off for one builder. Linking gRPC's reflection library
// registers its plugin for every builder in the process (a static initialiser), so a daemon
// with auth would list its API to callers without a token unless the plugin is removed here.
class ReflectionOption final : public grpc::ServerBuilderOption {
 public:
  explicit ReflectionOption(bool enabled) : enabled_(enabled) {}
  void UpdateArguments(grpc::ChannelArguments*) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    auto reflection = std::make_unique<grpc::reflection::ProtoServerReflectionPlugin>();
    const std::string name = reflection->name();
    std::erase_if(*plugins, [&](const std::unique_ptr<grpc::ServerBuilderPlugin>& plugin) {
      return plugin->name() == name;
    });
    if (enabled_) plugins->push_back(std::move(reflection));
  }

 private:
  bool enabled_;
};

// This process's lease holder id (core/storage/lease_policy.h): host, pid and 64 random bits,
// so a restarted daemon that got the same pid is still another holder.
std::string NewHolderId() {
  char host[HOST_NAME_MAX + 1] = {};
  if (::gethostname(host, sizeof(host) - 1) != 0) host[0] = '\0';
  std::random_device random;
  const uint64_t bits = (uint64_t{random()} << 32) ^ random();
  return MakeHolderId(host, ::getpid(), bits);
}

// The compute workers of DaemonOptions::backend / gpus, each with its own backend and queue.
absl::StatusOr<std::vector<std::unique_ptr<DeviceWorker>>> MakeWorkers(const DaemonOptions& o) {
  std::vector<std::unique_ptr<DeviceWorker>> workers;
  if (absl::Status apply = CheckGpusApply(o.backend, o.gpus.has_value()); !apply.ok()) {
    return apply;
  }
  std::vector<int> gpus;  // after the check, only with --backend cuda or auto
  if (o.gpus) {
    gpus = *o.gpus;
  } else if (o.backend != BackendKind::kCpu) {
    for (int i = 0; i < CudaDeviceCount(); ++i) gpus.push_back(i);
  }
  if (o.backend == BackendKind::kCuda && gpus.empty()) {
    // MakeBackend names the reason: no CUDA in this build, or no device visible.
    absl::StatusOr<std::unique_ptr<Backend>> probe = MakeBackend(BackendKind::kCuda, 0);
    return absl::FailedPreconditionError(absl::StrCat(
        "--backend cuda: ", probe.ok() ? "--gpus selects no device" : probe.status().message()));
  }
  if (gpus.empty()) {
    if (o.mapping_nice < 0 || o.mapping_nice > 19) {
      return absl::InvalidArgumentError(
          absl::StrCat("--mapping-nice must be in 0-19, got ", o.mapping_nice));
    }
    std::unique_ptr<Backend> cpu = MakeCpuBackend(o.threads);
    const int threads = cpu->parallelism();
    if (!o.mapping_worker) {
      DeviceDescription device{"cpu", "cpu", absl::StrCat("cpu (", threads, " threads)")};
      workers.push_back(std::make_unique<DeviceWorker>(std::move(cpu), std::move(device)));
      return workers;
    }
    DeviceDescription tracking{"cpu", "cpu",
                               absl::StrCat("cpu (", threads, " threads, interactive)"),
                               WorkerRole::kInteractive};
    // Its own pool of as many threads, so each worker can use every core the other leaves.
    std::unique_ptr<Backend> mapping_backend = MakeCpuBackend(threads, o.mapping_nice);
    DeviceDescription mapping{
        "cpu-mapping", "cpu",
        absl::StrCat("cpu (", threads, " threads, mapping, nice +", o.mapping_nice, ")"),
        WorkerRole::kMapping, o.mapping_nice};
    workers.push_back(std::make_unique<DeviceWorker>(std::move(cpu), std::move(tracking)));
    workers.push_back(
        std::make_unique<DeviceWorker>(std::move(mapping_backend), std::move(mapping)));
    return workers;
  }
  for (int id : gpus) {
    absl::StatusOr<std::unique_ptr<Backend>> gpu = MakeBackend(BackendKind::kCuda, id);
    if (!gpu.ok()) {
      return absl::FailedPreconditionError(absl::StrCat("--backend ", BackendKindText(o.backend),
                                                        ": cuda:", id, ": ",
                                                        gpu.status().message()));
    }
    DeviceDescription device{absl::StrCat("cuda:", id), "cuda", CudaDeviceName(id)};
    workers.push_back(std::make_unique<DeviceWorker>(std::move(*gpu), std::move(device)));
  }
  return workers;
}

}  // namespace

std::string PlenoxdVersion() { return PLX_VERSION; }

Daemon::Daemon() = default;

int Daemon::metrics_port() const { return http_ ? http_->port() : -1; }

absl::StatusOr<std::unique_ptr<Daemon>> Daemon::Start(const DaemonOptions& options) {
  // A bad certificate or key would otherwise only show as BuildAndStart failing, which reads
  // as "address in use".
  if (!options.tls_cert_pem.empty() || !options.tls_key_pem.empty()) {
    if (absl::Status s = CheckTlsPem({options.tls_cert_pem, options.tls_key_pem},
                                     "TLS certificate", "TLS private key");
        !s.ok()) {
      return s;
    }
  }
  // The viewer's files are checked before anything starts: a daemon asked for a viewer it
  // cannot serve says so at once.
  std::optional<web::ThreeJsFiles> three;
  if (options.viewer) {
    if (options.metrics_port < 0) {
      return absl::InvalidArgumentError(
          "--viewer is served on the HTTP port: give --metrics-port too (0 = a free port)");
    }
    absl::StatusOr<web::ThreeJsFiles> files = web::LoadThreeJs(options.viewer_three_dir);
    if (!files.ok()) {
      return absl::Status(files.status().code(),
                          absl::StrCat("--viewer: ", files.status().message()));
    }
    three = std::move(*files);
  }
  std::unique_ptr<Daemon> d(new Daemon());
  d->options_ = options;
  // The devices first: a daemon that cannot compute where it was told to stops before it
  // reads any map.
  absl::StatusOr<std::vector<std::unique_ptr<DeviceWorker>>> workers = MakeWorkers(options);
  if (!workers.ok()) return workers.status();
  d->workers_ = std::make_unique<WorkerPool>(std::move(*workers));
  if (!options.data_dir.empty() && !options.shared_dir.empty()) {
    return absl::InvalidArgumentError("--data-dir and --shared-dir: give one of them");
  }
  const auto make_dir = [](const char* flag, const std::string& dir) -> absl::Status {
    std::error_code ec;
    if (!dir.empty()) std::filesystem::create_directories(dir, ec);
    if (ec) return absl::InvalidArgumentError(absl::StrCat(flag, " ", dir, ": ", ec.message()));
    return absl::OkStatus();
  };
  PLX_RETURN_IF_ERROR(make_dir("--data-dir", options.data_dir));
  PLX_RETURN_IF_ERROR(make_dir("--shared-dir", options.shared_dir));
  MapStoreOptions store;
  store.data_dir = options.data_dir;
  store.max_maps = options.max_maps;
  store.max_map_bytes = options.max_map_bytes;
  store.test_only_save_delay = options.test_only_save_delay;
  std::shared_ptr<DirectoryMapStorage> shared;
  if (!options.shared_dir.empty()) {
    if (options.lease_term <= absl::ZeroDuration()) {
      return absl::InvalidArgumentError("--lease-seconds: must be above 0");
    }
    store.holder = NewHolderId();
    store.lease = LeaseTermsFor(options.lease_term);
    shared = std::make_shared<DirectoryMapStorage>(
        DirectoryStorageOptions{options.shared_dir, absl::Seconds(10), store.holder});
    store.shared = shared;
  }
  d->maps_ = std::make_unique<MapStore>(store);
  if (shared != nullptr) {
    // Staging files of writers that died between writing and publishing; an hour is far
    // longer than any save, and a live writer's file changes as it is written.
    for (const StaleTempFile& stale : shared->RemoveStaleStaging(absl::Hours(1), absl::Now())) {
      LogEvent(stale.removed.ok() ? "info" : "warning",
               stale.removed.ok() ? "stale_staging_removed" : "stale_staging_not_removed",
               {{"path", stale.path}, {"reason", std::string(stale.removed.message())}});
    }
    d->leases_ = std::make_unique<LeaseKeeper>(d->maps_.get(), store.lease.renew_every);
  }
  // Temporaries of saves a crash interrupted are never read again: remove them (and say so).
  for (const StaleTempFile& stale : d->maps_->RemoveStaleTempFiles()) {
    if (stale.removed.ok()) {
      LogEvent("info", "stale_temp_removed",
               {{"path", stale.path}, {"pid", std::to_string(stale.pid)}});
    } else {
      LogEvent("warning", "stale_temp_not_removed",
               {{"path", stale.path}, {"reason", std::string(stale.removed.message())}});
    }
  }
  for (const std::string& problem : d->maps_->LoadAllFromDataDir()) {
    LogEvent("warning", "map_not_loaded", {{"reason", problem}});
  }
  // The file-I/O worker (SaveMap, LoadMap): a DeviceWorker with no backend, outside the
  // WorkerPool, so a long write never queues ahead of tracking or mapping on a device.
  d->io_ = std::make_unique<DeviceWorker>(nullptr, DeviceDescription{"io", "io", "io"});
  d->jobs_ = std::make_unique<JobRegistry>();
  d->metrics_registry_ = std::make_unique<Metrics>();
  d->state_.maps = d->maps_.get();
  d->state_.workers = d->workers_.get();
  d->state_.io = d->io_.get();
  d->state_.jobs = d->jobs_.get();
  d->state_.metrics = d->metrics_registry_.get();
  d->slam_jobs_ = std::make_unique<SlamJobs>(&d->state_);
  d->state_.slam_jobs = d->slam_jobs_.get();
  d->state_.config.auth_token = options.auth_token;
  d->state_.config.max_streams = options.max_streams;
  d->state_.config.max_frame_pixels = options.max_frame_pixels;
  d->state_.config.max_render_pixels = options.max_render_pixels;
  d->state_.config.max_message_bytes = options.max_message_bytes;
  d->state_.config.version = PlenoxdVersion();
  d->state_.config.backend = BackendKindText(options.backend);
  d->state_.config.cuda_built = BuiltWithCuda();
  d->service_ = std::make_unique<PlenoxdService>(&d->state_);
  if (options.snapshot_interval > absl::ZeroDuration() &&
      (!options.data_dir.empty() || !options.shared_dir.empty())) {
    // Background work by nature: its thread yields the CPU to tracking like the mapping
    // worker's (nice is best effort, as there).
    d->snapshot_worker_ = std::make_unique<DeviceWorker>(
        nullptr, DeviceDescription{"snapshot", "io", "snapshot", WorkerRole::kAll,
                                   std::clamp(options.mapping_nice, 0, 19)});
    d->snapshots_ = std::make_unique<SnapshotScheduler>(
        d->maps_.get(), d->snapshot_worker_.get(), d->metrics_registry_.get(),
        options.snapshot_interval);
  }

  grpc::EnableDefaultHealthCheckService(true);
  std::shared_ptr<grpc::ServerCredentials> credentials;
  if (!options.tls_cert_pem.empty() || !options.tls_key_pem.empty()) {
    grpc::SslServerCredentialsOptions ssl;
    ssl.pem_key_cert_pairs.push_back({options.tls_key_pem, options.tls_cert_pem});
    credentials = grpc::SslServerCredentials(ssl);
  } else {
    credentials = grpc::InsecureServerCredentials();
  }
  grpc::ServerBuilder builder;
  // Reflection lists the API to anyone who asks; with authentication on it stays off, so only
  // the health service answers without a token.
  builder.SetOption(std::make_unique<ReflectionOption>(options.auth_token.empty()));
  // gRPC sets SO_REUSEPORT by default: a second daemon on a busy port would start and share
  // the connections; with it off, Start fails with "address in use".
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(options.listen, credentials, &d->port_);
  builder.RegisterService(d->service_.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.SetMaxSendMessageSize(options.max_message_bytes);
  d->server_ = builder.BuildAndStart();
  if (!d->server_ || d->port_ == 0) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options.listen,
                                               " (address in use, or not host:port?)"));
  }
  d->server_->GetHealthCheckService()->SetServingStatus(true);
  if (options.metrics_port >= 0) {
    web::HttpServerOptions http;
    http.host = options.metrics_host;
    http.port = options.metrics_port;
    d->http_ = std::make_unique<web::HttpServer>(http);
    Daemon* raw = d.get();
    AddMetricsRoute(*d->http_, [raw] { return raw->RenderMetrics(); });
    if (three) {
      web::ViewerOptions viewer;
      viewer.auth_token = options.auth_token;
      viewer.max_render_pixels = std::min(viewer.max_render_pixels, options.max_render_pixels);
      d->viewer_source_ =
          std::make_unique<DaemonViewerSource>(&d->state_, "plenoxd " + PlenoxdVersion());
      d->viewer_ = std::make_unique<web::Viewer>(d->viewer_source_.get(), std::move(*three),
                                                 viewer);
      d->viewer_->AddRoutes(*d->http_);
    }
    if (absl::Status s = d->http_->Start(); !s.ok()) {
      return absl::UnavailableError(absl::StrCat("metrics: ", s.message()));
    }
  }
  LogEvent("info", "serving",
           {{"listen", options.listen}, {"port", std::to_string(d->port_)},
            {"backend", BackendKindText(options.backend)},
            {"devices", absl::StrJoin(d->workers_->device_names(), ", ")},
            {"maps", std::to_string(d->maps_->size())},
            {"auth", options.auth_token.empty() ? "off" : "bearer"},
            {"tls", options.tls_cert_pem.empty() ? "off" : "on"},
            {"metrics_port", std::to_string(d->metrics_port())},
            {"viewer", options.viewer ? "on" : "off"},
            {"snapshot_s", d->snapshots_ != nullptr
                               ? absl::StrCat(absl::ToDoubleSeconds(options.snapshot_interval))
                               : "off"},
            {"shared_dir", options.shared_dir.empty() ? "off" : options.shared_dir},
            {"lease_holder", store.holder},
            {"lease_s", options.shared_dir.empty()
                            ? "off"
                            : absl::StrCat(absl::ToDoubleSeconds(options.lease_term))}});
  return d;
}

std::string Daemon::RenderMetrics() const {
  Metrics::Gauges g;
  g.maps = maps_->size();
  g.map_bytes = maps_->TotalBytes();
  g.queue_depth = workers_->total_queue_depth();
  g.jobs_running = jobs_->running();
  g.serving = !state_.draining.load();
  g.unsaved_maps = static_cast<int64_t>(maps_->DirtyNames().size());
  const absl::Time oldest = maps_->OldestUnsavedChange();
  g.unsaved_s =
      oldest == absl::InfiniteFuture() ? 0.0 : absl::ToDoubleSeconds(absl::Now() - oldest);
  g.leases_held = maps_->leases_held();
  g.lease_losses = maps_->lease_losses();
  g.fenced_saves_refused = maps_->fenced_saves_refused();
  g.handoffs_given = maps_->handoffs_given();
  g.handoffs_taken = maps_->handoffs_taken();
  for (const std::shared_ptr<SlamJob>& job : slam_jobs_->Running()) {
    const SlamJobStatus s = job->Status();
    ++g.slam_jobs;
    g.slam_pending_keyframes += s.mapping.pending_keyframes;
    g.slam_last_publish_s = std::max(g.slam_last_publish_s, s.mapping.last_publish_s);
    g.slam_loops += s.mapping.loops.accepted;
    g.slam_loops_rejected += s.mapping.loops.rejected;
    g.slam_corrections += s.mapping.loops.corrections;
    g.slam_last_solve_s = std::max(g.slam_last_solve_s, s.mapping.loops.last_solve_ms / 1e3);
  }
  for (size_t i = 0; i < workers_->size(); ++i) {
    const DeviceWorker& w = workers_->worker(i);
    g.devices.push_back({w.device().id, w.device().kind, w.device().name, w.queue_depth(),
                         w.streams()});
  }
  if (http_ != nullptr) g.http = http_->stats();
  return metrics_registry_->Render(g);
}

absl::Status Daemon::Drain(absl::Duration grace) {
  if (drained_) return absl::OkStatus();
  drained_ = true;
  LogEvent("info", "draining", {{"grace_s", absl::StrCat(absl::ToDoubleSeconds(grace))}});
  // No new snapshots: the drain saves every dirty map itself (below). One being written goes
  // on; the snapshot worker is stopped (and waited for) before that save.
  if (snapshots_ != nullptr) snapshots_->Stop();
  // Running calls get `grace` to finish; then gRPC cancels them, and they say so
  // (CancelledCallStatus).
  const absl::Time deadline = absl::Now() + grace;
  state_.drain_deadline_ns = absl::ToUnixNanos(deadline);
  state_.draining = true;
  server_->GetHealthCheckService()->SetServingStatus(false);
  // Workers keep running until the server is down, so queued frames and mapping chunks complete
  // or see their stream cancelled.
  server_->Shutdown(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(absl::ToInt64Milliseconds(grace)));
  // SLAM jobs integrate the keyframes their streams handed them (not the rest of their
  // optimisation budget) and publish, so the save below has every one; the workers must still
  // run for that. A Slam call ends after its job's done message, so this mostly happened
  // within Shutdown; what is left shares the same `grace` (never more in all: the stop
  // watchdog's budget is --drain-seconds + --stop-grace-seconds, server/stop_watchdog.h).
  if (!slam_jobs_->WaitForAll(std::max(absl::ZeroDuration(), deadline - absl::Now()))) {
    LogEvent("warning", "slam_jobs_not_finished",
             {{"jobs", absl::StrCat(slam_jobs_->Running().size())}});
  }
  workers_->StopAll();
  io_->Stop();
  if (snapshot_worker_ != nullptr) snapshot_worker_->Stop();
  // Every dirty map is tried; each one that could not be saved gets its own line.
  const std::vector<UnsavedMap> unsaved = maps_->SaveDirty();
  std::vector<std::string> names;
  for (const UnsavedMap& map : unsaved) {
    LogEvent("error", "map_not_saved",
             {{"map", map.name}, {"reason", std::string(map.reason.message())}});
    names.push_back(map.name);
  }
  // Shared storage: the saves above needed live leases; now they are given up, so another
  // daemon takes the maps at once instead of after their expiry.
  if (leases_ != nullptr) leases_->Stop();
  for (const MapLeaseEvent& event : maps_->ReleaseLeases()) {
    LogEvent("warning", "lease_not_released",
             {{"map", event.name}, {"reason", std::string(event.status.message())}});
  }
  http_.reset();
  LogEvent(unsaved.empty() ? "info" : "error", "stopped",
           {{"unsaved_maps", absl::StrJoin(names, ",")}});
  if (unsaved.empty()) return absl::OkStatus();
  return absl::Status(
      unsaved.front().reason.code(),
      absl::StrCat(unsaved.size(), " map(s) not saved: ", absl::StrJoin(names, ", "),
                   " (first error: ", unsaved.front().reason.message(), ")"));
}

std::vector<std::string> Daemon::UnsavedMaps() const { return maps_->DirtyNames(); }

Daemon::~Daemon() {
  if (server_ && !drained_) Drain(absl::Seconds(1)).IgnoreError();
}

}  // namespace plx::server

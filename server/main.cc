// plenoxd: the daemon. Serves plenoxd.v1 (maps, Integrate, Track, Render, Export, WatchJob), the
// standard health service and reflection, optional Prometheus metrics; drains on SIGTERM/SIGINT.
#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <mutex>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "app/flags.h"
#include "app/make_backend.h"
#include "core/geometry/intrinsics.h"
#include "server/daemon.h"
#include "server/secret_files.h"
#include "server/stop_watchdog.h"

namespace {

absl::Status FlagError(const char* flag, const absl::Status& status) {
  return absl::Status(status.code(), absl::StrCat(flag, ": ", status.message()));
}

int Usage(const absl::Status& status) {
  std::cerr << "plenoxd: " << status.message() << "\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  plx::FlagSet flags("plenoxd",
                     "The plenoxd daemon: RGB-D maps as Plenoxel radiance fields over gRPC.\n"
                     "Clients: `plenox --server HOST:PORT ...`, clients/python. Stops cleanly on\n"
                     "SIGTERM (drains, saves dirty maps to --data-dir, exits 0; 1 when a map\n"
                     "could not be saved, 3 when --drain-seconds + --stop-grace-seconds passed);\n"
                     "between, maps with unsaved changes are saved in the background\n"
                     "(--snapshot-seconds). Limits and their defaults: docs/LIMITS.md.");
  flags.Add("listen", "HOST:PORT", "address to serve on (0.0.0.0:PORT for all interfaces)",
            "127.0.0.1:50051")
      .Add("data-dir", "DIR", "maps are loaded from and saved to DIR/<name>.plx")
      .Add("shared-dir", "DIR",
           "instead of --data-dir: maps live in DIR on a volume several daemons share; a call "
           "naming a map this daemon does not hold loads it from DIR, and a map is written only "
           "by the daemon holding its lease (fencing token checked at every save; "
           "deploy/README.md)")
      .Add("lease-seconds", "S",
           "with --shared-dir: a map's lease lasts S seconds, renewed every S/3; a daemon that "
           "stops renewing loses its maps to another after S, and writes none of them after "
           "S*3/4 without a renewal",
           "15")
      .Add("snapshot-seconds", "S",
           "save a map with unsaved changes in the background once its oldest unsaved change "
           "is S seconds old (a published version, copy-on-write, written atomically; with "
           "--data-dir or --shared-dir): kill -9 loses at most about S seconds of mapping; "
           "0 = only SaveMap and SIGTERM save",
           "30")
      .Add("auth-token-file", "F",
           "require 'authorization: Bearer <token>' with the token in F (printable ASCII, no "
           "spaces; ends trimmed; keep F private, a readable F is logged)")
      .Add("tls-cert", "PEM",
           "serve TLS with this certificate chain (with --tls-key; both checked at start)")
      .Add("tls-key", "PEM", "unencrypted private key for --tls-cert")
      .Add("metrics-port", "PORT",
           "serve Prometheus metrics at http://HOST:PORT/metrics (-1 = off; 16 threads, 5 s "
           "read/write and 2 s idle timeouts)",
           "-1")
      .Add("metrics-host", "IP", "address for the metrics endpoint (and --viewer)", "127.0.0.1")
      .AddSwitch("viewer",
                 "serve the web map viewer at http://HOST:PORT/viewer/ on the --metrics-port "
                 "(maps, SLAM cameras, renders; with --auth-token-file open "
                 "/viewer/#token=<token>)")
      .Add("viewer-three-dir", "DIR",
           "where three.js is (Debian's libjs-three: three.min.js, "
           "examples/js/controls/OrbitControls.js and examples/js/loaders/GLTFLoader.js)",
           plx::web::kDefaultThreeJsDir)
      .Add("max-maps", "N", "maps held at once", "16")
      .Add("max-map-mb", "MB",
           "memory per map, checked before a keyframe's bricks or a loaded map are allocated",
           "4096")
      .Add("max-streams", "N", "concurrent streaming calls", "32")
      .Add("max-message-mb", "MB", "largest message accepted or sent", "64")
      .Add("max-frame-pixels", "N",
           "largest Track/Integrate frame, width x height (default 4K UHD, 3840x2160); larger "
           "frames get RESOURCE_EXHAUSTED before their images are decoded",
           "8294400")
      .Add("max-render-pixels", "N",
           "most pixels (width x height) one Render may ask for; more is RESOURCE_EXHAUSTED",
           std::to_string(plx::server::kDefaultMaxRenderPixels))
      .Add("backend", "cpu|cuda|auto",
           "compute backend: cuda = one worker per GPU of --gpus (fails at start without "
           "one); auto = cuda when a GPU is visible, else one CPU worker",
           "auto")
      .Add("gpus", "all|0,1,...", "CUDA devices to use with --backend cuda or auto", "all")
      .Add("threads", "N", "CPU threads of each CPU worker (0 = all cores)", "0")
      .Add("mapping-worker", "on|off",
           "CPU backend: a second worker for mapping (Integrate, SLAM mapping, Export) beside "
           "the one for tracking and rendering, so frames never wait behind a mapping step; "
           "off = one worker does both",
           "on")
      .Add("mapping-nice", "N",
           "OS priority of the CPU mapping worker's threads below the tracking ones (0-19; at "
           "10 mapping gets about a tenth of a core tracking wants, and every cycle it leaves)",
           "10")
      .Add("drain-seconds", "S", "how long running calls may finish on SIGTERM", "5")
      .Add("stop-grace-seconds", "S",
           "after --drain-seconds, how long saving dirty maps may take; then plenoxd logs each "
           "map not saved and exits 3",
           "30");
  std::vector<std::string> args(argv + 1, argv + argc);
  absl::StatusOr<bool> parsed = flags.Parse(args);
  if (!parsed.ok()) return Usage(parsed.status());
  if (!*parsed) {
    std::cout << flags.Usage();
    return 0;
  }
  plx::server::DaemonOptions options;
  options.listen = flags.GetString("listen");
  options.data_dir = flags.GetString("data-dir");
  options.metrics_host = flags.GetString("metrics-host");
  options.viewer = flags.GetSwitch("viewer");
  options.viewer_three_dir = flags.GetString("viewer-three-dir");
  if (flags.IsSet("viewer-three-dir") && !options.viewer) {
    return Usage(absl::InvalidArgumentError("--viewer-three-dir only applies with --viewer"));
  }
  auto metrics_port = flags.GetInt("metrics-port", -1, 65535);
  auto max_maps = flags.GetInt("max-maps", 1, 100000);
  auto max_map_mb = flags.GetInt("max-map-mb", 1, 1 << 24);
  auto max_streams = flags.GetInt("max-streams", 1, 100000);
  auto max_message_mb = flags.GetInt("max-message-mb", 1, 2047);
  // Frames and views are at most kMaxImageSide pixels a side (IntrinsicsFromProto).
  constexpr int kMaxImagePixels = plx::kMaxImageSide * plx::kMaxImageSide;
  auto max_frame_pixels = flags.GetInt("max-frame-pixels", 1, kMaxImagePixels);
  auto max_render_pixels = flags.GetInt("max-render-pixels", 1, kMaxImagePixels);
  auto threads = flags.GetInt("threads", 0, 4096);
  auto mapping_nice = flags.GetInt("mapping-nice", 0, 19);
  auto drain = flags.GetDouble("drain-seconds", 0.0, 3600.0);
  auto snapshot = flags.GetDouble("snapshot-seconds", 0.0, 86400.0);
  auto stop_grace = flags.GetDouble("stop-grace-seconds", 0.0, 86400.0);
  auto lease = flags.GetDouble("lease-seconds", 0.5, 3600.0);
  for (const absl::Status& s : {metrics_port.status(), max_maps.status(), max_map_mb.status(),
                                max_streams.status(), max_message_mb.status(),
                                max_frame_pixels.status(), max_render_pixels.status(),
                                threads.status(), mapping_nice.status(), drain.status(),
                                stop_grace.status(), snapshot.status(), lease.status()}) {
    if (!s.ok()) return Usage(s);
  }
  options.metrics_port = *metrics_port;
  options.shared_dir = flags.GetString("shared-dir");
  if (!options.data_dir.empty() && !options.shared_dir.empty()) {
    return Usage(absl::InvalidArgumentError("--data-dir and --shared-dir: give one of them"));
  }
  if (flags.IsSet("lease-seconds") && options.shared_dir.empty()) {
    return Usage(absl::InvalidArgumentError("--lease-seconds only applies with --shared-dir"));
  }
  options.lease_term = absl::Seconds(*lease);
  options.snapshot_interval = absl::Seconds(*snapshot);
  if (options.viewer && options.metrics_port < 0) {
    return Usage(absl::InvalidArgumentError(
        "--viewer is served on the HTTP port: give --metrics-port too (0 = a free port)"));
  }
  options.max_maps = *max_maps;
  options.max_map_bytes = int64_t{*max_map_mb} << 20;
  options.max_streams = *max_streams;
  options.max_message_bytes = *max_message_mb << 20;
  options.max_frame_pixels = *max_frame_pixels;
  options.max_render_pixels = *max_render_pixels;
  options.threads = *threads;
  options.mapping_nice = *mapping_nice;
  const std::string mapping_worker = flags.GetString("mapping-worker");
  if (mapping_worker != "on" && mapping_worker != "off") {
    return Usage(absl::InvalidArgumentError(
        absl::StrCat("--mapping-worker must be on or off, got \"", mapping_worker, "\"")));
  }
  options.mapping_worker = mapping_worker == "on";
  absl::StatusOr<plx::BackendKind> backend = plx::ParseBackendKind(flags.GetString("backend"));
  if (!backend.ok()) return Usage(backend.status());
  options.backend = *backend;
  if (absl::Status gpus_apply = plx::CheckGpusApply(options.backend, flags.IsSet("gpus"));
      !gpus_apply.ok()) {
    return Usage(gpus_apply);
  }
  if (flags.IsSet("gpus")) {
    absl::StatusOr<std::vector<int>> gpus = plx::ParseGpuList(flags.GetString("gpus"));
    if (!gpus.ok()) return Usage(gpus.status());
    options.gpus = *gpus;
  }
  // Secrets are checked here, each error naming its flag and file, before anything listens.
  if (flags.IsSet("auth-token-file")) {
    auto token = plx::server::ReadAuthTokenFile(flags.GetString("auth-token-file"));
    if (!token.ok()) return Usage(FlagError("--auth-token-file", token.status()));
    options.auth_token = *token;
  }
  // TEST ONLY, deliberately not a flag: tests of the stop watchdog make every save hang this
  // long (docs/LIMITS.md). Never set in production.
  if (const char* delay = std::getenv("PLENOXD_TEST_ONLY_SAVE_DELAY_S")) {
    double seconds = 0.0;
    if (!absl::SimpleAtod(delay, &seconds) || !(seconds >= 0.0)) {
      return Usage(absl::InvalidArgumentError("$PLENOXD_TEST_ONLY_SAVE_DELAY_S: not seconds"));
    }
    options.test_only_save_delay = absl::Seconds(seconds);
  }
  if (flags.IsSet("tls-cert") != flags.IsSet("tls-key")) {
    return Usage(absl::InvalidArgumentError("--tls-cert and --tls-key go together"));
  }
  if (flags.IsSet("tls-cert")) {
    auto tls = plx::server::ReadTlsFiles(flags.GetString("tls-cert"), flags.GetString("tls-key"));
    if (!tls.ok()) return Usage(FlagError("--tls-cert/--tls-key", tls.status()));
    options.tls_cert_pem = tls->cert_pem;
    options.tls_key_pem = tls->key_pem;
  }

  // Signals are taken by sigwait below, not by handlers, so they must be blocked before any
  // thread starts (threads inherit the mask).
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  absl::StatusOr<std::unique_ptr<plx::server::Daemon>> daemon = plx::server::Daemon::Start(options);
  if (!daemon.ok()) {
    std::cerr << "plenoxd: " << daemon.status().message() << "\n";
    return 1;
  }
  std::cout << "plenoxd listening on port " << (*daemon)->port();
  if ((*daemon)->metrics_port() >= 0) {
    std::cout << ", metrics on port " << (*daemon)->metrics_port();
  }
  std::cout << std::endl;
  if (options.viewer) {
    std::cout << "viewer: http://" << options.metrics_host << ":" << (*daemon)->metrics_port()
              << "/viewer/" << (options.auth_token.empty() ? "" : "#token=<token>") << std::endl;
  }

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  // Whatever the drain gets stuck on, the process ends within --drain-seconds plus
  // --stop-grace-seconds, naming the maps it could not save. The watchdog asks the daemon while
  // it exists, then the names the drain left behind.
  std::mutex unsaved_mutex;
  plx::server::Daemon* live = daemon->get();
  std::vector<std::string> left_unsaved;
  plx::server::StopWatchdog watchdog(absl::Seconds(*drain) + absl::Seconds(*stop_grace), [&] {
    std::lock_guard<std::mutex> lock(unsaved_mutex);
    return live != nullptr ? live->UnsavedMaps() : left_unsaved;
  });
  const absl::Status saved = (*daemon)->Drain(absl::Seconds(*drain));
  {
    std::lock_guard<std::mutex> lock(unsaved_mutex);
    left_unsaved = live->UnsavedMaps();
    live = nullptr;
  }
  daemon->reset();
  watchdog.Disarm();
  return saved.ok() ? 0 : 1;
}

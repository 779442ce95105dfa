// plenox view: the web viewer plenoxd serves (web/viewer_routes.h), for one map file and without
// a daemon: the map is loaded, a local HTTP server on 127.0.0.1 serves the page and its
// endpoints until Ctrl-C (SIGINT) or SIGTERM, and renders run on this process's backend.
#include <signal.h>

#include <filesystem>
#include <iostream>
#include <memory>
#include <chrono>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "core/grid/map_status.h"
#include "web/http_server.h"
#include "web/three_js.h"
#include "web/viewer_routes.h"
#include "web/viewer_source.h"

namespace plx::cli {
namespace {

// One map, loaded once and never changed (version 1), without SLAM cameras. Renders take turns
// on the one backend.
class FileViewerSource final : public web::ViewerSource {
 public:
  FileViewerSource(std::string name, std::string file, std::shared_ptr<const PlenoxelMap> map,
                   std::shared_ptr<const MapKeyframes> keyframes, std::unique_ptr<Backend> backend)
      : name_(std::move(name)),
        file_(std::move(file)),
        map_(std::move(map)),
        keyframes_(std::move(keyframes)),
        backend_(std::move(backend)) {}

  std::string Title() const override { return "plenox view " + file_; }

  std::vector<MapStatus> ListMaps() const override {
    MapStatus status = MapStatusOf(name_, *map_);
    status.version = 1;
    return {status};
  }

  absl::StatusOr<web::ViewerMap> Latest(const std::string& name) const override {
    if (name != name_) return absl::NotFoundError(absl::StrCat("no map \"", name, "\""));
    return web::ViewerMap{map_, 1, keyframes_};
  }

  absl::StatusOr<web::ViewerTrajectories> Trajectories(const std::string& name) const override {
    if (name != name_) return absl::NotFoundError(absl::StrCat("no map \"", name, "\""));
    web::ViewerTrajectories none;
    none.map_version = 1;
    return none;
  }

  // On this thread, one call at a time: there is one backend.
  absl::Status RunOnDevice(const DeviceWork& work, absl::Duration timeout) override {
    const absl::Time deadline = absl::Now() + timeout;
    std::unique_lock<std::timed_mutex> lock(backend_mutex_, std::defer_lock);
    if (!lock.try_lock_for(std::chrono::microseconds(absl::ToInt64Microseconds(timeout)))) {
      return absl::DeadlineExceededError("another request held the backend too long");
    }
    const absl::Status status = work(*backend_, [deadline] { return absl::Now() > deadline; });
    if (absl::IsCancelled(status)) return absl::DeadlineExceededError("did not finish in time");
    return status;
  }

 private:
  const std::string name_;
  const std::string file_;
  const std::shared_ptr<const PlenoxelMap> map_;
  const std::shared_ptr<const MapKeyframes> keyframes_;
  std::timed_mutex backend_mutex_;
  const std::unique_ptr<Backend> backend_;
};

}  // namespace

int RunView(const std::vector<std::string>& raw_args) {
  FlagSet flags("plenox view",
                "Opens the web viewer for a map file without a daemon: serves the page on\n"
                "127.0.0.1 (or --host), prints its URL and serves until Ctrl-C. The page shows\n"
                "the map's surface points in 3D (orbit, zoom) and renders colour and depth\n"
                "from any view. three.js comes from Debian's libjs-three (no download).\n"
                "Usage: plenox view MAP.plx [flags]");
  flags.Add("map", "MAP", "map file (or give it first, without the flag)")
      .Add("host", "IP", "address to serve on (0.0.0.0 for every interface: the page has no "
                         "authentication)", "127.0.0.1")
      .Add("port", "PORT", "port to serve on (0 = a free one, printed)", "0")
      .Add("viewer-three-dir", "DIR",
           "where three.js is (three.min.js, examples/js/controls/OrbitControls.js and "
           "examples/js/loaders/GLTFLoader.js)",
           web::kDefaultThreeJsDir);
  AddBackendFlags(flags);
  // `plenox view MAP.plx`: the map may come first, as a plain argument.
  std::vector<std::string> args = raw_args;
  if (!args.empty() && !args[0].empty() && args[0][0] != '-') {
    args[0] = "--map=" + args[0];
  }
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  if (!flags.IsSet("map")) {
    return ReportError("view", absl::InvalidArgumentError("give a map file: plenox view MAP.plx"),
                       true);
  }
  absl::StatusOr<int> port = flags.GetInt("port", 0, 65535);
  if (!port.ok()) return ReportError("view", port.status(), true);
  absl::StatusOr<web::ThreeJsFiles> three = web::LoadThreeJs(flags.GetString("viewer-three-dir"));
  if (!three.ok()) return ReportError("view", three.status());
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("view", flags, &exit_code);
  if (!backend) return exit_code;
  MapFileState state;
  std::unique_ptr<PlenoxelMap> map =
      LoadMapOrReport("view", flags, *backend, &exit_code, &state);
  if (!map) return exit_code;

  // SIGINT and SIGTERM are taken by sigwait below; blocked before the server's threads start
  // (they inherit the mask), so no thread dies of them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  const std::string file = flags.GetString("map");
  const std::string name = std::filesystem::path(file).stem().string();
  FileViewerSource source(name.empty() ? "map" : name, file,
                          std::shared_ptr<const PlenoxelMap>(std::move(map)),
                          std::make_shared<const MapKeyframes>(std::move(state.keyframes)),
                          std::move(backend));
  web::Viewer viewer(&source, std::move(*three), web::ViewerOptions{});
  web::HttpServerOptions http;
  http.host = flags.GetString("host");
  http.port = *port;
  {
    web::HttpServer server(http);
    viewer.AddRoutes(server);
    if (absl::Status s = server.Start(); !s.ok()) return ReportError("view", s);
    const std::string host = http.host.find(':') != std::string::npos ? "[" + http.host + "]"
                                                                      : http.host;
    std::cout << "plenox view: " << file << " at http://" << host << ":" << server.port()
              << "/viewer/ (Ctrl-C stops)" << std::endl;
    int signal_number = 0;
    sigwait(&stop_signals, &signal_number);
    std::cout << "plenox view: stopping" << std::endl;
  }
  return kExitOk;
}

}  // namespace plx::cli

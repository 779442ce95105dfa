// plenox: the command-line client. Maps, evaluates and renders RGB-D datasets in-process, or,
// with the global flag --server HOST:PORT, has a plenoxd daemon do the work on its maps.
#include <iostream>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "clients/plenox/commands.h"

namespace {

constexpr char kUsage[] =
    "usage: plenox <command> [flags]   (plenox <command> --help for its flags)\n"
    "       plenox --server HOST:PORT [--token-file F] [--tls-ca PEM] [--retry-seconds S]\n"
    "              <command> [flags]\n"
    "\n"
    "commands:\n"
    "  demo       generate a synthetic RGB-D sequence, map it, score held-out views, track it\n"
    "  map        build a map from a dataset with known poses\n"
    "  track      localise every frame of a dataset in a map (writes a TUM trajectory)\n"
    "  slam       online SLAM: poses for unposed frames while the map grows (TUM trajectory)\n"
    "  eval-map   score a map on a dataset's held-out frames (PSNR, depth L1, coverage)\n"
    "  eval-traj  compare an estimated trajectory with ground truth (ATE, RPE)\n"
    "  render     render colour and depth images of a map from a pose\n"
    "  synth      write the synthetic RGB-D sequence to a folder (TUM layout)\n"
    "  export     write a map file as a PLY point cloud or, with --mesh, a triangle mesh\n"
    "  view       open a map file in the web viewer (a local page; plenoxd --viewer for live "
    "maps)\n"
    "\n"
    "with --server, on the daemon's maps (map/slam --name N, track/render --map N):\n"
    "  map, track, slam, render, export   as above, the work done by the daemon\n"
    "  maps       list the daemon's maps\n"
    "  save       write a map to the daemon's data directory\n"
    "  load       read a map back from the daemon's data directory\n"
    "  info       the daemon's version, compute devices (CPU or GPUs) and map count\n"
    "\n"
    "global flags (before the command):\n"
    "  --server HOST:PORT  talk to the plenoxd daemon there (plenoxd's default: 127.0.0.1:50051)\n"
    "  --token-file F      bearer token for a daemon started with --auth-token-file\n"
    "  --tls-ca PEM        root certificate of a daemon serving TLS\n"
    "  --retry-seconds S   how long to wait for a daemon that went away (restarted, failed\n"
    "                      over): calls safe to repeat are retried with backoff, a slam stream\n"
    "                      reconnects and goes on in its map (default 30; 0: fail at once)\n";

// Commands that only exist against a daemon, and commands that only run in-process.
const std::set<std::string> kDaemonOnly = {"maps", "save", "load", "info"};
const std::set<std::string> kInProcessOnly = {"demo", "eval-map", "eval-traj", "synth", "view"};

int UsageError(const std::string& message) {
  std::cerr << "plenox: " << message << "\n(plenox --help for usage)\n";
  return 2;
}

// "HOST:PORT" with a port in 1-65535 (IPv6 hosts in brackets: [::1]:50051).
absl::Status CheckServerAddress(const std::string& address) {
  const size_t colon = address.rfind(':');
  const std::string host = colon == std::string::npos ? address : address.substr(0, colon);
  int port = 0;
  if (colon == std::string::npos || host.empty() ||
      !absl::SimpleAtoi(address.substr(colon + 1), &port) || port < 1 || port > 65535 ||
      address.substr(colon + 1).find_first_not_of("0123456789") != std::string::npos ||
      (host.find(':') != std::string::npos && host.front() != '[')) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--server: expected HOST:PORT (e.g. 127.0.0.1:50051), got \"", address, "\""));
  }
  return absl::OkStatus();
}

// Takes the global flags (--server, --token-file, --tls-ca, --retry-seconds; "--flag value" or
// "--flag=value") off the front of `args`.
absl::Status ParseGlobalFlags(std::vector<std::string>* args, plx::cli::RemoteOptions* remote) {
  std::string retry_seconds;
  const std::vector<std::pair<std::string, std::string*>> flags = {
      {"--server", &remote->server},
      {"--token-file", &remote->token_file},
      {"--tls-ca", &remote->tls_ca},
      {"--retry-seconds", &retry_seconds}};
  std::set<std::string> seen;
  size_t i = 0;
  while (i < args->size()) {
    const std::string& arg = (*args)[i];
    const size_t equals = arg.find('=');
    const std::string name = arg.substr(0, equals);
    std::string* target = nullptr;
    for (const auto& [flag, value] : flags) {
      if (flag == name) target = value;
    }
    if (target == nullptr) break;
    std::string value;
    if (equals != std::string::npos) {
      value = arg.substr(equals + 1);
      i += 1;
    } else {
      if (i + 1 >= args->size()) return absl::InvalidArgumentError(name + " needs a value");
      value = (*args)[i + 1];
      i += 2;
    }
    if (value.empty()) return absl::InvalidArgumentError(name + " needs a value");
    if (!seen.insert(name).second) {
      return absl::InvalidArgumentError(name + " is given more than once");
    }
    *target = value;
  }
  args->erase(args->begin(), args->begin() + static_cast<std::ptrdiff_t>(i));
  if (remote->server.empty()) {
    if (!remote->token_file.empty()) {
      return absl::InvalidArgumentError("--token-file only applies together with --server");
    }
    if (!remote->tls_ca.empty()) {
      return absl::InvalidArgumentError("--tls-ca only applies together with --server");
    }
    if (!retry_seconds.empty()) {
      return absl::InvalidArgumentError("--retry-seconds only applies together with --server");
    }
    return absl::OkStatus();
  }
  if (!retry_seconds.empty() &&
      (!absl::SimpleAtod(retry_seconds, &remote->retry_seconds) ||
       !(remote->retry_seconds >= 0.0 && remote->retry_seconds <= 86400.0))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--retry-seconds: expected seconds from 0 (no retries) to 86400, got \"", retry_seconds,
        "\""));
  }
  return CheckServerAddress(remote->server);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) {
    std::cerr << kUsage;
    return 2;
  }
  if (args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
    std::cout << kUsage;
    return 0;
  }
  plx::cli::RemoteOptions remote;
  if (absl::Status s = ParseGlobalFlags(&args, &remote); !s.ok()) {
    return UsageError(std::string(s.message()));
  }
  if (args.empty()) return UsageError("a command must follow the global flags");
  if (args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
    std::cout << kUsage;
    return 0;
  }
  const std::string command = args[0];
  args.erase(args.begin());
  const bool use_server = !remote.server.empty();
#ifndef PLX_WITH_SERVER
  if (use_server || kDaemonOnly.count(command) > 0) {
    return UsageError(absl::StrCat(
        use_server ? "--server" : command,
        " needs a plenox built with gRPC (configure with -DPLX_WITH_SERVER=ON; needs "
        "libgrpc++-dev and protobuf, see scripts/install_deps.sh); this build runs in-process "
        "only"));
  }
#else
  if (command == "map" && use_server) return plx::cli::RunRemoteMap(remote, args);
  if (command == "track" && use_server) return plx::cli::RunRemoteTrack(remote, args);
  if (command == "slam" && use_server) return plx::cli::RunRemoteSlam(remote, args);
  if (command == "render" && use_server) return plx::cli::RunRemoteRender(remote, args);
  if (command == "export" && use_server) return plx::cli::RunRemoteExport(remote, args);
  if (command == "maps") return plx::cli::RunRemoteMaps(remote, args);
  if (command == "save") return plx::cli::RunRemoteSave(remote, args);
  if (command == "load") return plx::cli::RunRemoteLoad(remote, args);
  if (command == "info") return plx::cli::RunRemoteInfo(remote, args);
  if (use_server && kInProcessOnly.count(command) > 0) {
    return UsageError(
        absl::StrCat(command, " runs in-process only; give it without --server"));
  }
#endif
  if (command == "map") return plx::cli::RunMap(args);
  if (command == "eval-map") return plx::cli::RunEvalMap(args);
  if (command == "eval-traj") return plx::cli::RunEvalTraj(args);
  if (command == "track") return plx::cli::RunTrack(args);
  if (command == "slam") return plx::cli::RunSlam(args);
  if (command == "render") return plx::cli::RunRender(args);
  if (command == "synth") return plx::cli::RunSynth(args);
  if (command == "export") return plx::cli::RunExport(args);
  if (command == "demo") return plx::cli::RunDemo(args);
  if (command == "view") return plx::cli::RunView(args);
  std::cerr << "plenox: unknown command \"" << command << "\"\n\n" << kUsage;
  return 2;
}

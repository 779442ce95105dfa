// The plenox subcommands; each takes its arguments after the command name and returns the
// process exit code.
#pragma once

#include <string>
#include <vector>

namespace plx::cli {

int RunMap(const std::vector<std::string>& args);
int RunEvalMap(const std::vector<std::string>& args);
int RunEvalTraj(const std::vector<std::string>& args);
int RunRender(const std::vector<std::string>& args);
int RunTrack(const std::vector<std::string>& args);
int RunSlam(const std::vector<std::string>& args);
int RunSynth(const std::vector<std::string>& args);
int RunDemo(const std::vector<std::string>& args);
int RunExport(const std::vector<std::string>& args);
// The web viewer for a map file (web/viewer_routes.h), served on 127.0.0.1 until Ctrl-C.
int RunView(const std::vector<std::string>& args);

// The global flags that point plenox at a daemon (given before the command). With an empty
// `server` everything runs in-process.
struct RemoteOptions {
  std::string server;      // --server HOST:PORT
  std::string token_file;  // --token-file F: bearer token for an authenticating daemon
  std::string tls_ca;      // --tls-ca PEM: root certificate of a TLS daemon
  // --retry-seconds S: how long a call waits for a daemon that answered before and went away
  // (restarted, failed over), and how long a Slam stream waits to reconnect (0: no retries;
  // app/retry_policy.h says which calls are retried and why).
  double retry_seconds = 30.0;
};

// The same commands against a plenoxd daemon (remote_*.cc; only in builds with gRPC, where
// PLX_WITH_SERVER is defined). maps, save, load and info exist only in this form; they
// print their --help without --server and otherwise say that they need it.
int RunRemoteMap(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteTrack(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteSlam(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteRender(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteExport(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteMaps(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteSave(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteLoad(const RemoteOptions& remote, const std::vector<std::string>& args);
int RunRemoteInfo(const RemoteOptions& remote, const std::vector<std::string>& args);

}  // namespace plx::cli

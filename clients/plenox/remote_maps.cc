// plenox --server HOST:PORT maps / save / load / info: the daemon's maps (ListMaps), writing a
// map to / reading it back from the daemon's data directory (SaveMap, LoadMap), and what the
// daemon is and computes on (GetServerInfo).
#include <algorithm>
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"

namespace plx::cli {
namespace {

JsonObject MapInfoJson(const pb::MapInfo& m) {
  JsonObject json;
  json.Add("name", m.name())
      .Add("voxel_size", static_cast<double>(m.voxel_size()))
      .Add("version", static_cast<int64_t>(m.version()))
      .Add("bricks", static_cast<int64_t>(m.bricks()))
      .Add("memory_bytes", static_cast<int64_t>(m.memory_bytes()))
      .Add("map_mb", m.memory_bytes() / 1e6)
      .Add("keyframes", static_cast<int64_t>(m.keyframes()))
      .AddBool("dirty", m.dirty())
      .AddBool("mapping", m.mapping())
      .Add("source", m.source());
  return json;
}

std::string MapInfoText(const pb::MapInfo& m) {
  return absl::StrFormat("version %d, %d bricks, %.1f MB, %d keyframes, voxel %g m%s", m.version(),
                         m.bricks(), m.memory_bytes() / 1e6, m.keyframes(), m.voxel_size(),
                         m.dirty() ? ", unsaved changes" : "");
}

// save and load: one map name, one unary call.
int RunSaveOrLoad(const char* command, const RemoteOptions& remote,
                  const std::vector<std::string>& args) {
  const bool save = std::string(command) == "save";
  FlagSet flags(absl::StrFormat("plenox %s", command),
                save ? "Needs --server: writes map N to the daemon's data directory\n"
                       "(<data-dir>/N.plx, atomically)."
                     : "Needs --server: reads map N back from the daemon's data directory\n"
                       "(<data-dir>/N.plx), replacing the copy in memory.");
  flags.Add("map", "N", "the map on the daemon", std::nullopt, true)
      .AddSwitch("json", "print the map's status as JSON on the last line of stdout");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  std::unique_ptr<RemoteClient> client = ConnectOrReport(command, remote, &exit_code);
  if (!client) return exit_code;
  const std::string name = flags.GetString("map");
  absl::StatusOr<pb::MapInfo> info = save ? client->SaveMap(name) : client->LoadMap(name);
  if (!info.ok()) return ReportError(command, info.status());
  if (flags.GetSwitch("json")) {
    std::cout << MapInfoJson(*info).str() << "\n";
  } else {
    std::cout << absl::StrFormat("%s \"%s\" on %s: %s\n", save ? "saved" : "loaded", name,
                                 client->server(), MapInfoText(*info));
  }
  return kExitOk;
}

}  // namespace

int RunRemoteMaps(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox maps",
                "Needs --server: lists the daemon's maps (name, voxel size, version, bricks,\n"
                "memory, keyframes, unsaved changes, whether a mapping job is writing it).");
  flags.AddSwitch("json", "one JSON object per map, one per line (JSON Lines)");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  std::unique_ptr<RemoteClient> client = ConnectOrReport("maps", remote, &exit_code);
  if (!client) return exit_code;
  absl::StatusOr<std::vector<pb::MapInfo>> maps = client->ListMaps();
  if (!maps.ok()) return ReportError("maps", maps.status());
  std::sort(maps->begin(), maps->end(),
            [](const pb::MapInfo& a, const pb::MapInfo& b) { return a.name() < b.name(); });
  if (flags.GetSwitch("json")) {
    for (const pb::MapInfo& m : *maps) std::cout << MapInfoJson(m).str() << "\n";
    return kExitOk;
  }
  if (maps->empty()) {
    std::cout << "no maps on " << client->server() << "\n";
    return kExitOk;
  }
  size_t name_width = 4;
  for (const pb::MapInfo& m : *maps) name_width = std::max(name_width, m.name().size());
  const int w = static_cast<int>(name_width);
  std::cout << absl::StrFormat("%-*s  %8s  %8s  %9s  %9s  %9s  %5s  %7s\n", w, "NAME", "VOXEL_M",
                               "VERSION", "BRICKS", "MB", "KEYFRAMES", "DIRTY", "MAPPING");
  for (const pb::MapInfo& m : *maps) {
    std::cout << absl::StrFormat("%-*s  %8g  %8d  %9d  %9.1f  %9d  %5s  %7s\n", w, m.name(),
                                 m.voxel_size(), m.version(), m.bricks(), m.memory_bytes() / 1e6,
                                 m.keyframes(), m.dirty() ? "yes" : "no",
                                 m.mapping() ? "yes" : "no");
  }
  return kExitOk;
}

int RunRemoteInfo(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox info",
                "Needs --server: the daemon's version, its compute devices (one worker each:\n"
                "the CPU, or each GPU it was started with) with their queued tasks and bound\n"
                "streams, and how many maps it holds.");
  flags.AddSwitch("json",
                  "one JSON object for the daemon, then one per device (JSON Lines)");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  std::unique_ptr<RemoteClient> client = ConnectOrReport("info", remote, &exit_code);
  if (!client) return exit_code;
  absl::StatusOr<pb::ServerInfo> info = client->GetServerInfo();
  if (!info.ok()) return ReportError("info", info.status());
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("server", client->server())
        .Add("version", info->version())
        .Add("backend", info->backend())
        .AddBool("cuda_built", info->cuda_built())
        .Add("maps", static_cast<int64_t>(info->maps()))
        .Add("devices", info->devices_size());
    std::cout << json.str() << "\n";
    for (const pb::Device& d : info->devices()) {
      JsonObject device;
      device.Add("device", d.id())
          .Add("kind", d.kind())
          .Add("name", d.name())
          .Add("queue_depth", static_cast<int64_t>(d.queue_depth()))
          .Add("streams", static_cast<int64_t>(d.streams()));
      std::cout << device.str() << "\n";
    }
    return kExitOk;
  }
  std::cout << absl::StrFormat("plenoxd %s on %s: backend %s%s, %d maps, %d devices\n",
                               info->version(), client->server(), info->backend(),
                               info->cuda_built() ? "" : " (built without CUDA)", info->maps(),
                               info->devices_size());
  for (const pb::Device& d : info->devices()) {
    std::cout << absl::StrFormat("  %-11s %-5s %s  (queue %d, streams %d)\n", d.id(), d.kind(),
                                 d.name(), d.queue_depth(), d.streams());
  }
  return kExitOk;
}

int RunRemoteSave(const RemoteOptions& remote, const std::vector<std::string>& args) {
  return RunSaveOrLoad("save", remote, args);
}

int RunRemoteLoad(const RemoteOptions& remote, const std::vector<std::string>& args) {
  return RunSaveOrLoad("load", remote, args);
}

}  // namespace plx::cli

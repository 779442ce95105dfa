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
int RunSynth(const std::vector<std::string>& args);
int RunDemo(const std::vector<std::string>& args);

}  // namespace plx::cli

// plenox: the command-line client. Maps, evaluates and renders RGB-D datasets in-process.
#include <iostream>
#include <string>
#include <vector>

#include "clients/plenox/commands.h"

namespace {

constexpr char kUsage[] =
    "usage: plenox <command> [flags]   (plenox <command> --help for its flags)\n"
    "\n"
    "commands:\n"
    "  demo       generate a synthetic RGB-D sequence, map it, score held-out views, track it\n"
    "  map        build a map from a dataset with known poses\n"
    "  track      localise every frame of a dataset in a map (writes a TUM trajectory)\n"
    "  eval-map   score a map on a dataset's held-out frames (PSNR, depth L1, coverage)\n"
    "  eval-traj  compare an estimated trajectory with ground truth (ATE, RPE)\n"
    "  render     render colour and depth images of a map from a pose\n"
    "  synth      write the synthetic RGB-D sequence to a folder (TUM layout)\n";

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
  const std::string command = args[0];
  args.erase(args.begin());
  if (command == "map") return plx::cli::RunMap(args);
  if (command == "eval-map") return plx::cli::RunEvalMap(args);
  if (command == "eval-traj") return plx::cli::RunEvalTraj(args);
  if (command == "track") return plx::cli::RunTrack(args);
  if (command == "render") return plx::cli::RunRender(args);
  if (command == "synth") return plx::cli::RunSynth(args);
  if (command == "demo") return plx::cli::RunDemo(args);
  std::cerr << "plenox: unknown command \"" << command << "\"\n\n" << kUsage;
  return 2;
}

// Pieces shared by the plenox subcommands: terminal progress, JSON output, error reporting,
// and the flags every dataset-reading command accepts.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "app/flags.h"
#include "core/kernels/backend.h"
#include "core/datasets/dataset.h"
#include "core/formats/map_file.h"
#include "core/mapping/mapper.h"
#include "core/slam/slam_session.h"
#include "core/tracking/tracker.h"

namespace plx::cli {

// Exit codes: 0 success, 1 the work failed, 2 the command line was wrong.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

// Prints "plenox <command>: <message>" to stderr and returns the exit code for the status
// (usage errors from flag parsing are kExitUsage).
int ReportError(const std::string& command, const absl::Status& status, bool usage_error = false);

// Parses flags; on --help prints usage and sets *exit_code to 0; on error prints it and sets 2.
// Returns true when the command should run.
bool ParseFlagsOrExit(FlagSet& flags, const std::vector<std::string>& args, int* exit_code);

// A flag of a command's in-process form that its --server form cannot honour, and what to do
// instead ("the map stays on the daemon: --save writes it to the daemon's data directory").
struct UnavailableFlag {
  std::string name;  // without the dashes
  std::string instead;
};
// InvalidArgument "--NAME is not available with --server: INSTEAD" for the first of `flags`
// found in `args` (as "--NAME" or "--NAME=value"). Called before parsing, so that such a flag
// is refused with the reason rather than as an unknown flag, and never silently ignored.
absl::Status RefuseUnavailableFlags(const std::vector<std::string>& args,
                                    const std::vector<UnavailableFlag>& flags);

// One-line progress on stderr: rewritten in place on a terminal, a new line every few seconds
// otherwise (logs, CI).
class ProgressLine {
 public:
  explicit ProgressLine(bool enabled = true);
  void Update(const std::string& text);
  void Finish(const std::string& text);  // final line, always printed

 private:
  bool enabled_;
  bool tty_;
  std::chrono::steady_clock::time_point last_print_;
  size_t last_length_ = 0;
};

// A flat JSON object written in insertion order.
class JsonObject {
 public:
  JsonObject& Add(const std::string& key, double value);
  JsonObject& Add(const std::string& key, int64_t value);
  JsonObject& Add(const std::string& key, int value) { return Add(key, int64_t{value}); }
  JsonObject& Add(const std::string& key, const std::string& value);
  // true / false. Not an Add overload: a string literal would convert to bool before string.
  JsonObject& AddBool(const std::string& key, bool value);
  // Every field of `other`, in its order.
  JsonObject& Append(const JsonObject& other);
  std::string str() const;

 private:
  std::vector<std::pair<std::string, std::string>> fields_;
};

// Peak resident set size of this process, MB.
double PeakRssMb();

// --json (a JSON summary on the last line of stdout) and --quiet (no progress on stderr).
void AddJsonAndQuietSwitches(FlagSet& flags);

// --dataset, --format, --intrinsics, --depth-scale.
void AddDatasetFlags(FlagSet& flags);
// Checks the dataset flags (errors here are usage errors) ...
absl::StatusOr<DatasetOptions> DatasetOptionsFromFlags(const FlagSet& flags);
// ... and opens the dataset with them. Errors here are failures: it prints the error
// ("plenox <command>: ...") and returns nullptr with *exit_code set.
std::unique_ptr<RgbdDataset> OpenDatasetOrReport(const std::string& command, const FlagSet& flags,
                                                 const DatasetOptions& options, int* exit_code);

// NotFound when the folder that would hold `path` does not exist (checked before long work).
absl::Status CheckOutputDirectory(const std::string& path);

// --voxel-size, --time-budget, --iterations, --batch, --max-depth, --seed. Without
// --iterations the budget is kDefaultIterationsPerKeyframe (core/mapping/mapping_session.h) per
// keyframe.
void AddMapperFlags(FlagSet& flags);
// The iteration budget is set for `keyframes` keyframes; call again (or SetIterationBudget) once
// the real count is known.
absl::StatusOr<MapperOptions> MapperOptionsFromFlags(const FlagSet& flags, int keyframes);
void SetIterationBudget(const FlagSet& flags, int keyframes, MapperOptions* options);

// --mode gn|adam, --rays N, --iterations N: the tracker's settings, for in-process and remote
// tracking alike (unset flags keep the mode's defaults, TrackerOptionsForMode).
void AddTrackerFlags(FlagSet& flags);
absl::StatusOr<TrackerOptions> TrackerOptionsFromFlags(const FlagSet& flags);

// --backend cpu|cuda|auto, --device N, --threads N: where an in-process command computes.
void AddBackendFlags(FlagSet& flags);
// Makes the backend the flags ask for (app/make_backend.h). On an error it prints it
// ("plenox <command>: ...") and returns nullptr with *exit_code set: usage (2) for a bad flag
// value (--backend bogus, --device -1, --device with --backend cpu), failure (1) when the
// backend cannot be made (--backend cuda in a build without CUDA or on a machine without the
// device). Call it before any long work so such errors come at once.
// The map file of --map, with exact occupancy for `backend` (readers need it; see
// core/kernels/refresh_occupancy.h); null after reporting the error (exit code 1). With
// `state`, the file's keyframes and version number go there.
std::unique_ptr<PlenoxelMap> LoadMapOrReport(const std::string& command, const FlagSet& flags,
                                             Backend& backend, int* exit_code,
                                             MapFileState* state = nullptr);

// `default_threads`: the CPU backend's threads when --threads is not given (0: all cores).
std::unique_ptr<Backend> BackendFromFlagsOrReport(const std::string& command,
                                                  const FlagSet& flags, int* exit_code,
                                                  int default_threads = 0);
// The backend SLAM's mapping thread makes for itself (core/slam/slam_session.h): the kind and
// device of the backend flags (already checked by BackendFromFlagsOrReport). A CPU backend with
// 0 threads is the process-wide pool, which runs one loop at a time, so mapping gets a pool of
// its own with as many threads as the cores; `deterministic` asks for one thread (a fixed order
// of gradient adds). `default_threads` replaces "as many as the cores" when --threads is not
// given.
SlamSession::BackendFactory MappingBackendFactory(const FlagSet& flags, bool deterministic,
                                                  int default_threads = 0);

// The backend for progress and summary lines: "cpu, 4 threads", or the GPU's name.
std::string BackendText(const Backend& backend);

// "12.3 MB"-style text.
std::string Megabytes(int64_t bytes);

}  // namespace plx::cli

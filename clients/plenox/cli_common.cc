#include "clients/plenox/cli_common.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <iostream>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/match.h"
#include "absl/strings/str_format.h"
#include "app/make_backend.h"
#include "clients/plenox/map_flags.h"
#include "core/common/status_macros.h"
#include "core/formats/map_file.h"
#include "core/kernels/refresh_occupancy.h"
#include "core/mapping/mapping_session.h"

namespace plx::cli {

int ReportError(const std::string& command, const absl::Status& status, bool usage_error) {
  std::cerr << "plenox " << command << ": " << status.message() << "\n";
  return usage_error ? kExitUsage : kExitFailure;
}

bool ParseFlagsOrExit(FlagSet& flags, const std::vector<std::string>& args, int* exit_code) {
  absl::StatusOr<bool> parsed = flags.Parse(args);
  if (!parsed.ok()) {
    std::cerr << flags.command() << ": " << parsed.status().message() << "\n";
    *exit_code = kExitUsage;
    return false;
  }
  if (!*parsed) {
    std::cout << flags.Usage();
    *exit_code = kExitOk;
    return false;
  }
  return true;
}

absl::Status RefuseUnavailableFlags(const std::vector<std::string>& args,
                                    const std::vector<UnavailableFlag>& flags) {
  for (const std::string& arg : args) {
    for (const UnavailableFlag& flag : flags) {
      const std::string dashed = "--" + flag.name;
      if (arg == dashed || absl::StartsWith(arg, dashed + "=")) {
        return absl::InvalidArgumentError(
            absl::StrCat(dashed, " is not available with --server: ", flag.instead));
      }
    }
  }
  return absl::OkStatus();
}

ProgressLine::ProgressLine(bool enabled)
    : enabled_(enabled), tty_(isatty(STDERR_FILENO) != 0),
      last_print_(std::chrono::steady_clock::now() - std::chrono::hours(1)) {}

void ProgressLine::Update(const std::string& text) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  if (tty_) {
    if (now - last_print_ < std::chrono::milliseconds(100)) return;
    std::string padded = text;
    if (padded.size() < last_length_) padded.append(last_length_ - padded.size(), ' ');
    std::cerr << "\r" << padded << std::flush;
    last_length_ = text.size();
  } else {
    if (now - last_print_ < std::chrono::seconds(5)) return;
    std::cerr << text << "\n" << std::flush;
  }
  last_print_ = now;
}

void ProgressLine::Finish(const std::string& text) {
  if (!enabled_) return;
  if (tty_ && last_length_ > 0) {
    std::string padded = text;
    if (padded.size() < last_length_) padded.append(last_length_ - padded.size(), ' ');
    std::cerr << "\r" << padded << "\n" << std::flush;
  } else {
    std::cerr << text << "\n" << std::flush;
  }
  last_length_ = 0;
}

JsonObject& JsonObject::Add(const std::string& key, double value) {
  fields_.emplace_back(key, std::isfinite(value) ? absl::StrFormat("%.6g", value) : "null");
  return *this;
}

JsonObject& JsonObject::Add(const std::string& key, int64_t value) {
  fields_.emplace_back(key, absl::StrCat(value));
  return *this;
}

JsonObject& JsonObject::Add(const std::string& key, const std::string& value) {
  std::string escaped = "\"";
  for (char c : value) {
    switch (c) {
      case '"': escaped += "\\\""; break;
      case '\\': escaped += "\\\\"; break;
      case '\n': escaped += "\\n"; break;
      case '\t': escaped += "\\t"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          escaped += absl::StrFormat("\\u%04x", c);
        } else {
          escaped += c;
        }
    }
  }
  escaped += "\"";
  fields_.emplace_back(key, escaped);
  return *this;
}

JsonObject& JsonObject::AddBool(const std::string& key, bool value) {
  fields_.emplace_back(key, value ? "true" : "false");
  return *this;
}

JsonObject& JsonObject::Append(const JsonObject& other) {
  fields_.insert(fields_.end(), other.fields_.begin(), other.fields_.end());
  return *this;
}

std::string JsonObject::str() const {
  std::string out = "{";
  for (size_t i = 0; i < fields_.size(); ++i) {
    absl::StrAppend(&out, i ? ", " : "", "\"", fields_[i].first, "\": ", fields_[i].second);
  }
  return out + "}";
}

double PeakRssMb() {
  struct rusage usage;
  if (getrusage(RUSAGE_SELF, &usage) != 0) return 0.0;
  return usage.ru_maxrss / 1024.0;  // Linux reports kilobytes
}

void AddBackendFlags(FlagSet& flags) {
  flags.Add("backend", "cpu|cuda|auto",
            "compute backend; auto = a CUDA GPU when this build has CUDA and one is visible, "
            "else the CPU",
            "auto")
      .Add("device", "N", "CUDA device for --backend cuda or auto", "0")
      .Add("threads", "N", "CPU threads of the CPU backend (0 = all cores)", "0");
}

std::unique_ptr<PlenoxelMap> LoadMapOrReport(const std::string& command, const FlagSet& flags,
                                             Backend& backend, int* exit_code,
                                             MapFileState* state) {
  absl::StatusOr<LoadedMapFile> file = LoadMapFile(flags.GetString("map"));
  absl::Status status = file.status();
  if (status.ok()) status = RefreshOccupancyIfStale(backend, *file->map);
  if (!status.ok()) {
    *exit_code = ReportError(command, status);
    return nullptr;
  }
  if (state != nullptr) *state = std::move(file->state);
  return std::move(file->map);
}

std::unique_ptr<Backend> BackendFromFlagsOrReport(const std::string& command,
                                                  const FlagSet& flags, int* exit_code,
                                                  int default_threads) {
  absl::StatusOr<BackendKind> kind = ParseBackendKind(flags.GetString("backend"));
  if (!kind.ok()) {
    *exit_code = ReportError(command, kind.status(), true);
    return nullptr;
  }
  absl::StatusOr<int> device = flags.GetInt("device", 0, 1023);
  if (!device.ok()) {
    *exit_code = ReportError(command, device.status(), true);
    return nullptr;
  }
  if (flags.IsSet("device") && *kind == BackendKind::kCpu) {
    *exit_code = ReportError(
        command, absl::InvalidArgumentError("--device only applies with --backend cuda or auto"),
        true);
    return nullptr;
  }
  absl::StatusOr<int> threads = flags.GetInt("threads", 0, 4096);
  if (!threads.ok()) {
    *exit_code = ReportError(command, threads.status(), true);
    return nullptr;
  }
  if (!flags.IsSet("threads")) *threads = default_threads;
  absl::StatusOr<std::unique_ptr<Backend>> backend = MakeBackend(*kind, *device, *threads);
  if (!backend.ok()) {
    *exit_code = ReportError(
        command, absl::Status(backend.status().code(),
                              absl::StrCat("--backend ", flags.GetString("backend"), ": ",
                                           backend.status().message())));
    return nullptr;
  }
  return std::move(*backend);
}

SlamSession::BackendFactory MappingBackendFactory(const FlagSet& flags, bool deterministic,
                                                  int default_threads) {
  const BackendKind kind =
      ParseBackendKind(flags.GetString("backend")).value_or(BackendKind::kAuto);
  const int device = flags.GetInt("device", 0, 1023).value_or(0);
  int threads = flags.GetInt("threads", 0, 4096).value_or(0);
  if (!flags.IsSet("threads")) threads = default_threads;
  if (threads == 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (deterministic) threads = 1;
  return [kind, device, threads] { return MakeBackend(kind, device, threads); };
}

std::string BackendText(const Backend& backend) {
  const std::string name = backend.name();
  if (name == "cpu") return absl::StrCat("cpu, ", backend.parallelism(), " threads");
  return name;
}

std::string Megabytes(int64_t bytes) { return absl::StrFormat("%.1f MB", bytes / 1e6); }

void AddJsonAndQuietSwitches(FlagSet& flags) {
  flags.AddSwitch("json", "print a JSON summary on the last line of stdout")
      .AddSwitch("quiet", "no progress on stderr");
}

void AddDatasetFlags(FlagSet& flags) {
  flags.Add("dataset", "DIR", "RGB-D sequence folder", std::nullopt, true)
      .Add("format", "auto|tum|replica|scannet", "dataset layout", "auto")
      .Add("intrinsics", "\"fx fy cx cy w h\"",
           "camera intrinsics, overriding the dataset's intrinsics.txt")
      .Add("depth-scale", "S", "depth units per metre (with --intrinsics; TUM 5000)", "5000");
}

absl::StatusOr<DatasetOptions> DatasetOptionsFromFlags(const FlagSet& flags) {
  DatasetOptions options;
  PLX_ASSIGN_OR_RETURN(options.format, ParseDatasetFormat(flags.GetString("format")));
  if (!flags.GetString("intrinsics").empty()) {
    CameraCalibration calibration;
    PLX_ASSIGN_OR_RETURN(calibration.pinhole,
                         ParsePinholeIntrinsics(flags.GetString("intrinsics")));
    PLX_ASSIGN_OR_RETURN(calibration.depth_scale, flags.GetDouble("depth-scale", 1e-6, 1e9));
    options.calibration = calibration;
  } else if (flags.GetString("depth-scale") != "5000") {
    return absl::InvalidArgumentError("--depth-scale only applies together with --intrinsics");
  }
  return options;
}

std::unique_ptr<RgbdDataset> OpenDatasetOrReport(const std::string& command,
                                                 const FlagSet& flags,
                                                 const DatasetOptions& options, int* exit_code) {
  absl::StatusOr<std::unique_ptr<RgbdDataset>> dataset =
      OpenDataset(flags.GetString("dataset"), options);
  if (!dataset.ok()) {
    *exit_code = ReportError(command, dataset.status());
    return nullptr;
  }
  return std::move(*dataset);
}

absl::Status CheckOutputDirectory(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (parent.empty() || std::filesystem::is_directory(parent)) return absl::OkStatus();
  return absl::NotFoundError(absl::StrCat("cannot write ", path, ": folder ", parent.string(),
                                          " does not exist"));
}

void AddTrackerFlags(FlagSet& flags) {
  flags.Add("mode", "gn|adam", "Gauss-Newton/LM, or Adam as in the paper", "gn")
      .Add("rays", "N", "rays per frame (adam: per step) [default: gn 2048, adam 4096]", "")
      .Add("iterations", "N", "iterations per frame [default: gn 8, adam 90]", "")
      .Add("pixels", "informative|uniform",
           "where gn casts its rays: spread, towards texture and off depth edges, or uniform "
           "over valid depth",
           "informative");
}

absl::StatusOr<TrackerOptions> TrackerOptionsFromFlags(const FlagSet& flags) {
  const std::string mode = flags.GetString("mode");
  if (mode != "gn" && mode != "adam") {
    return absl::InvalidArgumentError(
        absl::StrFormat("--mode must be gn or adam, got \"%s\"", mode));
  }
  TrackerOptions options =
      TrackerOptionsForMode(mode == "adam" ? TrackingMode::kAdam : TrackingMode::kGaussNewton);
  if (flags.IsSet("rays")) {
    PLX_ASSIGN_OR_RETURN(options.rays, flags.GetInt("rays", kMinTrackerRays, kMaxTrackerRays));
  }
  if (flags.IsSet("iterations")) {
    PLX_ASSIGN_OR_RETURN(options.iterations, flags.GetInt("iterations", 1, kMaxTrackerIterations));
  }
  const std::string pixels = flags.GetString("pixels");
  if (pixels != "informative" && pixels != "uniform") {
    return absl::InvalidArgumentError(
        absl::StrFormat("--pixels must be informative or uniform, got \"%s\"", pixels));
  }
  options.sampling =
      pixels == "uniform" ? PixelSampling::kUniform : PixelSampling::kInformative;
  return options;
}

void AddMapperFlags(FlagSet& flags) {
  AddVoxelSizeFlag(flags, "voxel edge in metres");
  flags.Add("time-budget", "S", "optimisation time limit in seconds (0 = none)", "0")
      .Add("iterations", "N",
           absl::StrCat("optimisation iteration limit (0 = none) [default: ",
                        kDefaultIterationsPerKeyframe, " per keyframe]"),
           "");
  AddBatchAndMaxDepthFlags(flags);
  flags.Add("seed", "N", "random seed for ray sampling", "20200823")
      .AddSwitch("coarse-to-fine",
                 "optimise at twice the voxel size for the first half, then upsample");
}

void SetIterationBudget(const FlagSet& flags, int keyframes, MapperOptions* options) {
  if (!flags.IsSet("iterations")) {
    options->max_iterations = std::max(1, kDefaultIterationsPerKeyframe * keyframes);
  }
}

absl::StatusOr<MapperOptions> MapperOptionsFromFlags(const FlagSet& flags, int keyframes) {
  PLX_ASSIGN_OR_RETURN(const double voxel, VoxelSizeFromFlags(flags));
  MapperOptions o = MapperOptionsForVoxelSize(static_cast<float>(voxel));
  PLX_ASSIGN_OR_RETURN(o.time_budget_s, flags.GetDouble("time-budget", 0.0, 1e7));
  if (flags.IsSet("iterations")) {
    PLX_ASSIGN_OR_RETURN(o.max_iterations, flags.GetInt("iterations", 0, 100000000));
  }
  SetIterationBudget(flags, keyframes, &o);
  PLX_ASSIGN_OR_RETURN(o.batch_size, BatchFromFlags(flags));
  PLX_ASSIGN_OR_RETURN(const double max_depth, MaxDepthFromFlags(flags));
  o.allocation.max_depth = static_cast<float>(max_depth);
  o.fusion.max_depth = static_cast<float>(max_depth);
  PLX_ASSIGN_OR_RETURN(const int seed, flags.GetInt("seed", 0, 2147483647));
  o.seed = static_cast<uint32_t>(seed);
  o.coarse_to_fine = flags.GetSwitch("coarse-to-fine");
  PLX_RETURN_IF_ERROR(Mapper::ValidateOptions(o));
  return o;
}

}  // namespace plx::cli

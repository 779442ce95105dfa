// plenox map: build a map from a dataset's keyframes with their ground-truth poses.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/map_flags.h"
#include "clients/plenox/mapping_progress.h"
#include "core/eval/map_metrics.h"
#include "core/formats/map_file.h"
#include "core/mapping/map_dataset.h"

namespace plx::cli {

int RunMap(const std::vector<std::string>& args) {
  FlagSet flags("plenox map",
                "Builds a Plenoxel map from every N-th frame of a dataset, using the dataset's\n"
                "ground-truth poses, and saves it to a map file.");
  AddDatasetFlags(flags);
  flags.Add("out", "MAP", "map file to write", std::nullopt, true);
  AddEveryFlag(flags, "N");
  AddMapperFlags(flags);
  AddBackendFlags(flags);
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<int> every = EveryFromFlags(flags);
  if (!every.ok()) return ReportError("map", every.status(), true);
  absl::StatusOr<MapperOptions> options = MapperOptionsFromFlags(flags, /*keyframes=*/1);
  if (!options.ok()) return ReportError("map", options.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError("map", dataset_options.status(), true);
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError("map", s);
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("map", flags, &exit_code);
  if (!backend) return exit_code;

  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport("map", flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  const std::vector<int> keyframes = KeyframeIndices(dataset->size(), *every);
  SetIterationBudget(flags, static_cast<int>(keyframes.size()), &*options);

  ProgressLine line(!flags.GetSwitch("quiet"));
  absl::StatusOr<MapDatasetResult> result =
      MapDataset(*dataset, keyframes, *options, *backend, MappingProgressPrinter(&line));
  if (!result.ok()) return ReportError("map", result.status());
  line.Finish(MappingSummaryText(result->summary) + " [" + BackendText(*backend) + "]");

  MapFileState state;
  state.keyframes = std::move(result->keyframes);  // for the observed surface's mesh
  if (absl::Status s = SaveMap(*result->map, state, out); !s.ok()) return ReportError("map", s);

  const MappingSummary& sum = result->summary;
  const double seconds = result->load_s + sum.allocation_s + sum.optimization_s;
  const double map_mb = sum.memory.total_bytes() / 1e6;
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("map", out)
        .Add("keyframes", sum.keyframes)
        .Add("training_rays", sum.training_rays)
        .Add("iterations", sum.iterations)
        .Add("bricks", sum.memory.bricks)
        .Add("seconds", seconds)
        .Add("seconds_load", result->load_s)
        .Add("seconds_allocate", sum.allocation_s)
        .Add("seconds_optimize", sum.optimization_s)
        .Add("seconds_per_keyframe", (sum.allocation_s + sum.optimization_s) / sum.keyframes)
        .Add("map_mb", map_mb)
        .Add("peak_rss_mb", PeakRssMb())
        .Add("backend", backend->name())
        .Add("threads", backend->parallelism());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("wrote %s: %d keyframes, %d bricks, %.1f MB, %.1f s\n", out,
                                 sum.keyframes, sum.memory.bricks, map_mb, seconds);
  }
  return kExitOk;
}

}  // namespace plx::cli

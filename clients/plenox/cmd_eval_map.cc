// plenox eval-map: score a map on the frames held out from mapping.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "core/eval/map_metrics.h"

namespace plx::cli {

int RunEvalMap(const std::vector<std::string>& args) {
  FlagSet flags("plenox eval-map",
                "Renders a map at the ground-truth poses of the frames held out from mapping\n"
                "(index % every == every / 2) and compares with their measured colour and\n"
                "depth: PSNR, depth L1 (range vs range, metres) and coverage (fraction of valid\n"
                "measured pixels the map renders).");
  flags.Add("map", "MAP", "map file", std::nullopt, true);
  AddDatasetFlags(flags);
  flags.Add("every", "N", "the map was built from every N-th frame", "10")
      .Add("frames", "N", "evaluate at most N held-out frames, evenly spread (0 = all)", "0")
      .Add("pixels", "N", "random valid-depth pixels per frame (0 = all of them)", "10000")
      .Add("max-depth", "M", "ignore measured depth beyond this (metres)", "10")
      .AddSwitch("json", "print the result as JSON");
  AddBackendFlags(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<int> every = flags.GetInt("every", 1, 1000000);
  absl::StatusOr<int> frames = flags.GetInt("frames", 0, 1000000);
  absl::StatusOr<int> pixels = flags.GetInt("pixels", 0, 100000000);
  absl::StatusOr<double> max_depth = flags.GetDouble("max-depth", 0.1, 1000.0);
  for (const absl::Status& s :
       {every.status(), frames.status(), pixels.status(), max_depth.status()}) {
    if (!s.ok()) return ReportError("eval-map", s, true);
  }

  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError("eval-map", dataset_options.status(), true);
  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("eval-map", flags, &exit_code);
  if (!backend) return exit_code;

  std::unique_ptr<PlenoxelMap> map = LoadMapOrReport("eval-map", flags, *backend, &exit_code);
  if (!map) return exit_code;
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport("eval-map", flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  const std::vector<int> held_out = HeldOutFrames(dataset->size(), *every, *frames);
  if (held_out.empty()) {
    return ReportError("eval-map", absl::FailedPreconditionError(absl::StrFormat(
                                       "the dataset has no frame held out from mapping every %d-th "
                                       "frame (%d frames)",
                                       *every, dataset->size())));
  }
  MapEvalOptions options;
  options.pixels_per_frame = *pixels;
  options.max_depth = *max_depth;
  absl::StatusOr<MapEvalResult> r = EvaluateMap(*backend, *map, *dataset, held_out, options);
  if (!r.ok()) return ReportError("eval-map", r.status());
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("psnr", r->psnr)
        .Add("depth_l1_m", r->depth_l1_m)
        .Add("depth_l1_median_m", r->depth_l1_median_m)
        .Add("coverage", r->coverage)
        .Add("frames", r->frames)
        .Add("pixels", r->pixels)
        .Add("backend", backend->name());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat(
        "held-out frames %d, pixels %d: PSNR %.2f dB, depth L1 %.2f cm (median %.2f cm), "
        "coverage %.3f [%s]\n",
        r->frames, r->pixels, r->psnr, 100 * r->depth_l1_m, 100 * r->depth_l1_median_m,
        r->coverage, BackendText(*backend));
  }
  return kExitOk;
}

}  // namespace plx::cli

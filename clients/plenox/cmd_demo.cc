// plenox demo: the embedded default job. Generates a synthetic RGB-D sequence, maps every 10th
// frame, scores the map on the frames in between, renders one of them, and says where
// everything went.
#include <filesystem>
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/mapping_progress.h"
#include "clients/plenox/synthetic_flags.h"
#include "core/eval/map_metrics.h"
#include "core/io/image_io.h"
#include "core/formats/map_file.h"
#include "core/mapping/map_dataset.h"
#include "core/eval/trajectory_metrics.h"
#include "core/formats/trajectory_file.h"
#include "core/render/render_view.h"
#include "core/slam/slam_dataset.h"
#include "core/tracking/track_dataset.h"

namespace plx::cli {

int RunDemo(const std::vector<std::string>& args) {
  FlagSet flags(
      "plenox demo",
      "Generates a synthetic RGB-D sequence with sensor-like depth noise, maps every\n"
      "10th frame with known poses, scores the map on the held-out frames in between\n"
      "(PSNR, depth L1, coverage), tracks every frame in the map (ATE), runs online SLAM\n"
      "on the same frames without their poses (ATE), and writes the sequence, the map,\n"
      "renders and both trajectories to --out.");
  flags.Add("out", "DIR", "output folder", "plenox_demo");
  AddSyntheticFlags(flags, 90, /*noise_by_default=*/true);
  AddMapperFlags(flags);
  flags.Add("every", "N", "map every N-th frame", "10");
  AddBackendFlags(flags);
  flags.AddSwitch("json", "print the metrics as JSON on the last line of stdout");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<SyntheticOptions> synth = SyntheticOptionsFromFlags(flags);
  if (!synth.ok()) return ReportError("demo", synth.status(), true);
  absl::StatusOr<int> every_flag = flags.GetInt("every", 1, 1000);
  const int demo_keyframes =
      every_flag.ok() ? static_cast<int>(KeyframeIndices(synth->num_frames, *every_flag).size())
                      : 1;
  absl::StatusOr<MapperOptions> options = MapperOptionsFromFlags(flags, demo_keyframes);
  if (!options.ok()) return ReportError("demo", options.status(), true);
  absl::StatusOr<int> every = flags.GetInt("every", 1, 1000);
  if (!every.ok()) return ReportError("demo", every.status(), true);
  if (HeldOutFrames(synth->num_frames, *every).empty()) {
    return ReportError("demo",
                       absl::InvalidArgumentError(absl::StrFormat(
                           "--frames %d with --every %d leaves no held-out frame to score (need "
                           "at least %d frames)",
                           synth->num_frames, *every, *every / 2 + 1)),
                       true);
  }

  std::unique_ptr<Backend> backend = BackendFromFlagsOrReport("demo", flags, &exit_code);
  if (!backend) return exit_code;

  const std::filesystem::path out = flags.GetString("out");
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) {
    return ReportError("demo", absl::InvalidArgumentError(absl::StrFormat(
                                   "cannot create %s: %s", out.string(), ec.message())));
  }
  ProgressLine line;
  line.Finish(absl::StrFormat("generating %d synthetic frames (%dx%d)...", synth->num_frames,
                              synth->width, synth->height));
  absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(*synth);
  if (!dataset.ok()) return ReportError("demo", dataset.status());
  const std::string sequence_dir = (out / "sequence").string();
  if (absl::Status s = WriteTumDataset(*dataset, sequence_dir); !s.ok()) {
    return ReportError("demo", s);
  }

  const std::vector<int> keyframes = KeyframeIndices(dataset->size(), *every);
  absl::StatusOr<MapDatasetResult> mapped =
      MapDataset(*dataset, keyframes, *options, *backend, MappingProgressPrinter(&line));
  if (!mapped.ok()) return ReportError("demo", mapped.status());
  line.Finish(MappingSummaryText(mapped->summary) + " [" + BackendText(*backend) + "]");
  const std::string map_path = (out / "map.plx").string();
  MapFileState state;
  state.keyframes = mapped->keyframes;  // their poses make the observed surface's mesh
  if (absl::Status s = SaveMap(*mapped->map, state, map_path); !s.ok()) {
    return ReportError("demo", s);
  }

  const std::vector<int> held_out = HeldOutFrames(dataset->size(), *every);
  MapEvalOptions eval_options;
  eval_options.pixels_per_frame = 0;  // every valid pixel
  absl::StatusOr<MapEvalResult> eval =
      EvaluateMap(*backend, *mapped->map, *dataset, held_out, eval_options);
  if (!eval.ok()) return ReportError("demo", eval.status());

  // One held-out view, rendered next to what the sensor saw.
  const int shown = held_out[held_out.size() / 2];
  const RgbdFrame& truth = dataset->frames()[shown];
  absl::StatusOr<RenderedView> rendered = RenderView(*backend, *mapped->map,
                                                     *truth.ground_truth,
                                                     dataset->calibration().pinhole);
  if (!rendered.ok()) return ReportError("demo", rendered.status());
  const RenderedView& view = *rendered;
  const std::string render_color = (out / "heldout_render_color.png").string();
  const std::string render_depth = (out / "heldout_render_depth.png").string();
  const std::string truth_color = (out / "heldout_sensor_color.png").string();
  const std::string truth_depth = (out / "heldout_sensor_depth.png").string();
  for (const absl::Status& s : {WriteColorImage(render_color, view.color),
                                WriteDepthImage(render_depth, view.z_depth, 1000.0),
                                WriteColorImage(truth_color, truth.color),
                                WriteDepthImage(truth_depth, truth.depth, 1000.0)}) {
    if (!s.ok()) return ReportError("demo", s);
  }

  // Localisation: every frame tracked in the map from frame 0's ground truth.
  int done = 0;
  absl::StatusOr<TrackDatasetResult> tracked = TrackDataset(
      *dataset, *mapped->map, *backend, TrackerOptions(), [&](int i, const TrackingResult& r) {
        line.Update(absl::StrFormat("tracking %d/%d  %s  %.0f ms", i + 1, dataset->size(),
                                    TrackingStateName(r.state), r.milliseconds));
        done = i + 1;
        return true;
      });
  if (!tracked.ok()) return ReportError("demo", tracked.status());
  line.Finish(absl::StrFormat("tracked %d frames: median %.1f ms per frame, %d lost", done,
                              tracked->ms_per_frame_median, tracked->lost));
  const std::string trajectory_path = (out / "trajectory.txt").string();
  if (absl::Status s = WriteTumTrajectory(trajectory_path, tracked->trajectory,
                                          "plenox demo: tracked synthetic sequence");
      !s.ok()) {
    return ReportError("demo", s);
  }
  std::vector<StampedPose> ground_truth;
  for (const RgbdFrame& f : dataset->frames()) {
    ground_truth.push_back({f.timestamp, *f.ground_truth});
  }
  absl::StatusOr<TrajectoryEvalResult> ate = EvaluateTrajectory(tracked->trajectory, ground_truth);
  if (!ate.ok()) return ReportError("demo", ate.status());

  // Online SLAM on the same frames, their poses unknown (only frame 0's, as the start).
  // Lock-step: the demo's sequence lasts a second and its frames are tiny, so a camera that
  // never waits would be carried by the odometry through most of it before mapping (niced)
  // published a version; mapping each keyframe before the next frame shows the map growing.
  // (Mapping keeps its threads: bit-identical runs would need one, at 3x the demo's time.)
  SlamDatasetOptions slam_options;
  slam_options.slam.deterministic = true;
  slam_options.slam.mapping.mapper = *options;
  slam_options.slam.mapping.mapper.window_keyframes =
      DefaultSlamOptions().mapping.mapper.window_keyframes;
  absl::StatusOr<SlamDatasetResult> slam = RunSlamOnDataset(
      *dataset, *backend, MappingBackendFactory(flags, false), slam_options,
      [&](const SlamFrameResult& r) {
        line.Update(absl::StrFormat("slam %d/%d  %s  %.0f ms  keyframes %d", r.frame + 1,
                                    dataset->size(), SlamStateName(r.state), r.milliseconds,
                                    r.keyframes));
        return true;
      });
  if (!slam.ok()) return ReportError("demo", slam.status());
  const std::string slam_path = (out / "slam_trajectory.txt").string();
  if (absl::Status s = WriteTumTrajectory(slam_path, slam->trajectory,
                                          "plenox demo: SLAM on the synthetic sequence");
      !s.ok()) {
    return ReportError("demo", s);
  }
  absl::StatusOr<TrajectoryEvalResult> slam_ate =
      EvaluateTrajectory(slam->trajectory, ground_truth);
  if (!slam_ate.ok()) return ReportError("demo", slam_ate.status());
  line.Finish(absl::StrFormat("slam: %d frames, %d keyframes, %d lost, ATE %.2f mm",
                              static_cast<int>(slam->trajectory.size()),
                              slam->progress.mapping.keyframes, slam->progress.tracking.lost,
                              1000 * slam_ate->ate.translation_m.rmse));

  const MappingSummary& sum = mapped->summary;
  std::cout << absl::StrFormat(
      "\nplenox demo: %d synthetic frames, %d keyframes mapped, %d held-out frames scored\n"
      "  backend      %s\n"
      "  mapping      %.1f s (%.2f s per keyframe), %d bricks, map %s\n"
      "  held-out     PSNR %.2f dB, depth L1 %.2f cm (median %.2f cm), coverage %.3f\n"
      "  tracking     %d frames, ATE %.2f mm (no alignment), median %.1f ms per frame, %d lost\n"
      "  slam         %d frames, ATE %.2f mm (no alignment), %d keyframes, %d lost, %.1f frames/s\n"
      "  outputs      %s\n"
      "    sequence   %s (TUM layout)\n"
      "    map        %s\n"
      "    renders    %s, %s (frame %d; sensor: %s, %s)\n"
      "    trajectory %s (TUM format)\n"
      "    slam       %s (TUM format)\n",
      dataset->size(), sum.keyframes, eval->frames, BackendText(*backend),
      sum.allocation_s + sum.optimization_s,
      (sum.allocation_s + sum.optimization_s) / sum.keyframes, sum.memory.bricks,
      Megabytes(sum.memory.total_bytes()), eval->psnr, 100 * eval->depth_l1_m,
      100 * eval->depth_l1_median_m, eval->coverage, dataset->size(),
      1000 * ate->ate.translation_m.rmse, tracked->ms_per_frame_median, tracked->lost,
      static_cast<int>(slam->trajectory.size()), 1000 * slam_ate->ate.translation_m.rmse,
      slam->progress.mapping.keyframes, slam->progress.tracking.lost,
      slam->wall_s > 0 ? slam->trajectory.size() / slam->wall_s : 0.0, out.string(),
      sequence_dir, map_path,
      render_color, render_depth, shown, truth_color, truth_depth, trajectory_path, slam_path);
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("frames", dataset->size())
        .Add("keyframes", sum.keyframes)
        .Add("heldout_frames", eval->frames)
        .Add("mapping_seconds", sum.allocation_s + sum.optimization_s)
        .Add("psnr", eval->psnr)
        .Add("depth_l1_m", eval->depth_l1_m)
        .Add("depth_l1_median_m", eval->depth_l1_median_m)
        .Add("coverage", eval->coverage)
        .Add("ate_rmse_m", ate->ate.translation_m.rmse)
        .Add("ms_per_frame_median", tracked->ms_per_frame_median)
        .Add("lost", tracked->lost)
        .Add("slam_ate_rmse_m", slam_ate->ate.translation_m.rmse)
        .Add("slam_keyframes", slam->progress.mapping.keyframes)
        .Add("slam_lost", slam->progress.tracking.lost)
        .Add("map", map_path)
        .Add("backend", backend->name());
    std::cout << json.str() << "\n";
  }
  return kExitOk;
}

}  // namespace plx::cli
